"""`visualenv distill`: a pixel student taught by a state-only teacher (DAgger), its fitting and its run folder."""

import csv
import hashlib
import json
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
import torch
from click.testing import CliRunner
from stable_baselines3.common.policies import ActorCriticCnnPolicy

from visualenv.cli import main
from visualenv.errors import ConfigError
from visualenv.train.distill import (
    STUDENT_ENCODERS,
    DistillConfig,
    _FeatureTap,
    _fit,
    _replay,
    _Rows,
    _shifted,
    _StateProbe,
    _student,
    _warped,
)
from visualenv.train.encoders import DrQEncoder
from visualenv.train.model_files import load_policy_file, save_policy
from visualenv.train.run_settings import SETTINGS


def _images_and_labels(n: int, discrete: bool) -> tuple[np.ndarray, np.ndarray]:
    """Images with a bright square on the left or the right; the label says which side."""
    generator = np.random.default_rng(0)
    frames = generator.integers(0, 40, (n, 3, 36, 36), dtype=np.uint8)
    left = generator.random(n) < 0.5
    frames[left, :, 10:26, 2:14] = 255
    frames[~left, :, 10:26, 22:34] = 255
    labels = left.astype(np.int64) if discrete else np.where(left, 0.5, -0.5).astype(np.float32)[:, None]
    return frames, labels


@pytest.mark.parametrize("discrete, rotate", [(False, 0.0), (True, 0.0), (False, 10.0)])
def test_the_student_learns_what_the_images_show(discrete, rotate):
    torch.manual_seed(0)
    frames, labels = _images_and_labels(64, discrete)
    actions = gym.spaces.Discrete(2) if discrete else gym.spaces.Box(-1, 1, (1,), np.float32)
    student = ActorCriticCnnPolicy(gym.spaces.Box(0, 255, (3, 36, 36), np.uint8), actions, lambda _: 0.0)
    config = DistillConfig(spec="", teacher="", epochs=1, batch_size=32, shift=2, rotate=rotate, zoom=rotate / 100)
    optimizer = torch.optim.Adam(student.parameters(), lr=1e-3)
    generator = np.random.default_rng(0)
    gathered = frames, labels, np.zeros((len(frames), 2), np.float32)
    first = _fit(student, optimizer, gathered, config, generator)
    for _ in range(30):
        last = _fit(student, optimizer, gathered, config, generator)
    assert last < first / 5, (first, last)
    chosen = student.predict(frames, deterministic=True)[0]
    expected = labels if discrete else np.sign(labels)
    assert np.mean((chosen if discrete else np.sign(chosen)) == expected) == 1.0


def test_the_state_loss_teaches_the_encoder_what_the_action_does_not_say():
    """Every label is the same action, so only the probe's state (which side the square is on) can shape the features:
    the encoder gets the probe's gradient, its loss falls, and the policy's own modules are all that is saved."""
    torch.manual_seed(0)
    frames, sides = _images_and_labels(64, discrete=False)
    space = gym.spaces.Box(0, 255, (3, 36, 36), np.uint8)
    student = ActorCriticCnnPolicy(space, gym.spaces.Box(-1, 1, (1,)), lambda _: 0.0)
    saved_keys = set(student.state_dict())
    probe = _StateProbe(student, 1)

    def probe_loss() -> torch.Tensor:
        with _FeatureTap(student) as features:
            student.get_distribution(torch.from_numpy(frames).float())
            return probe.loss(features.output, sides, sides.mean(axis=0), sides.std(axis=0))

    probe_loss().backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in student.features_extractor.parameters())
    student.zero_grad()
    first = probe_loss().item()
    optimizer = torch.optim.Adam([*student.parameters(), *probe.head.parameters()], lr=1e-3)
    config = DistillConfig(spec="", teacher="", epochs=1, batch_size=32, shift=2, state_loss=1.0)
    generator = np.random.default_rng(0)
    for _ in range(30):
        _fit(student, optimizer, (frames, np.zeros((64, 1), np.float32), sides), config, generator, probe)
    assert probe_loss().item() < first / 5
    assert set(student.state_dict()) == saved_keys
    with _FeatureTap(student) as tap:
        student.get_distribution(torch.from_numpy(frames[:2]).float())
        assert tap.output is not None
    student.get_distribution(torch.from_numpy(frames[:2]).float())
    assert tap.output is None  # its hook is gone on leaving


def test_the_consistency_loss_draws_a_distracted_frames_features_to_its_clean_twins():
    """The same images with and without a random bar drawn over them, fitted with and without the consistency loss
    from the same start: with it, each distracted image's features end nearer its clean twin's, measured against the
    spread of the features over the images (a loss that shrank every feature alike would not count)."""
    frames, labels = _images_and_labels(64, discrete=False)
    distracted = frames.copy()
    generator = np.random.default_rng(1)
    for image, row in zip(distracted, generator.integers(0, 30, len(frames))):
        image[:, row : row + 6, :] = generator.integers(0, 256, (3, 1, 1))  # a bar of a random colour
    space = gym.spaces.Box(0, 255, (3, 36, 36), np.uint8)

    def distance_after(consistency: float) -> float:
        torch.manual_seed(0)
        student = ActorCriticCnnPolicy(space, gym.spaces.Box(-1, 1, (1,)), lambda _: 0.0)
        optimizer = torch.optim.Adam(student.parameters(), lr=1e-3)
        config = DistillConfig(spec="", teacher="", epochs=1, batch_size=32, shift=2, consistency=consistency)
        rng = np.random.default_rng(0)
        for _ in range(30):
            _fit(student, optimizer, (distracted, labels, np.zeros((64, 1), np.float32)), config, rng, clean=frames)
        with torch.no_grad():
            seen, twin = (
                student.extract_features(torch.from_numpy(x), student.features_extractor) for x in (distracted, frames)
            )
        return (torch.nn.functional.mse_loss(seen, twin) / twin.var(dim=0).mean()).item()

    assert distance_after(1.0) < distance_after(0.0) / 2  # 2.8-3.6 times nearer with seeds 0-2


def test_the_twin_replays_an_episode_and_refuses_one_whose_state_it_does_not_reach():
    """The twin steps through the episode's actions, each of its frames kept once its state is the episode's."""
    at = {"state": np.zeros(2, np.float32)}

    def step(action):
        at["state"] = at["state"] + action
        return (np.full((1, 1), at["state"][0]),)

    env = SimpleNamespace(state_observation=lambda: at["state"])
    twin = SimpleNamespace(unwrapped=SimpleNamespace(envs=[SimpleNamespace(unwrapped=env)]), step=step)
    actions = [np.ones(2, np.float32), np.full(2, 2, np.float32)]
    cleans: list = []
    last = _replay(twin, np.zeros((1, 1)), actions, [np.zeros(2), np.ones(2)], cleans)
    assert [c.item() for c in cleans] == [0.0, 1.0] and last.item() == 3.0
    with pytest.raises(ConfigError, match="undistracted twin's state left the distracted env's"):
        _replay(twin, last, actions, [np.full(2, 3.0), np.zeros(2)], [])


def test_the_students_encoder_is_kept_in_its_policy_file_and_a_start_of_another_encoder_is_refused(tmp_path):
    spaces = SimpleNamespace(
        observation_space=gym.spaces.Box(0, 255, (6, 36, 36), np.uint8), action_space=gym.spaces.Box(-1, 1, (1,))
    )
    student = _student(spaces, encoder="drq")
    assert type(student.features_extractor) is DrQEncoder and student.features_extractor.features_dim == 50
    student.to(memory_format=torch.contiguous_format)
    save_policy(student, tmp_path / "drq.safetensors", half=False, algorithm="dagger")
    loaded = load_policy_file(tmp_path / "drq.safetensors", "distill")
    assert type(loaded.features_extractor) is DrQEncoder
    again = _student(spaces, loaded, "drq")  # a later segment of the same encoder starts from its weights
    assert all(torch.equal(a, b) for a, b in zip(again.state_dict().values(), loaded.state_dict().values()))
    with pytest.raises(ConfigError, match="encodes its frames with DrQEncoder; --encoder nature is NatureCNN"):
        _student(spaces, loaded, "nature")
    assert SETTINGS["encoder"].choices == STUDENT_ENCODERS  # config.json takes the names --encoder does


def test_the_rounds_rows_read_as_their_concatenation_in_the_order_asked():
    rng = np.random.default_rng(0)
    parts = [rng.integers(0, 256, (n, 2, 3), dtype=np.uint8) for n in (5, 1, 7)]
    rows = _Rows()
    for part in parts:
        rows.append(part)
    whole = np.concatenate(parts)
    asked = rng.integers(0, len(whole), 40)
    assert len(rows) == 13 and rows.shape == (13, 2, 3)
    np.testing.assert_array_equal(rows[asked], whole[asked])
    np.testing.assert_array_equal(rows[np.array([12, 0, 5, 5, 6])], whole[[12, 0, 5, 5, 6]])


def test_random_shift_moves_each_image_by_at_most_the_shift():
    images = torch.zeros((200, 1, 9, 9), dtype=torch.uint8)
    images[:, 0, 4, 4] = 255
    shifted = _shifted(images, 2, np.random.default_rng(0))
    assert shifted.shape == images.shape and shifted.dtype == torch.uint8
    moved = {tuple(int(v) for v in np.argwhere(img[0].numpy() == 255)[0]) for img in shifted}
    assert moved == {(y, x) for y in range(2, 7) for x in range(2, 7)}  # every offset of -2..2 drawn, none further
    assert _shifted(images, 0, np.random.default_rng(0)) is images


def _spot_polar(images: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    """The distance (pixels) and direction (degrees) of each image's bright spot from the image's centre."""
    weights = images[:, 0].numpy()
    height, width = weights.shape[1:]
    ys, xs = np.mgrid[0:height, 0:width]
    total = weights.sum(axis=(1, 2))
    y = (weights * ys).sum(axis=(1, 2)) / total - (height - 1) / 2
    x = (weights * xs).sum(axis=(1, 2)) / total - (width - 1) / 2
    return np.hypot(x, y), np.degrees(np.arctan2(y, x))


def test_warp_turns_and_scales_each_image_within_its_bounds_its_frames_alike():
    # a wide image (the turn must stay rigid in pixels) with a spot 15 pixels right of its centre, in two frames
    images = torch.zeros((300, 2, 41, 61), dtype=torch.uint8)
    images[:, :, 19:22, 44:47] = 255

    turned = _warped(images, 30, 0, np.random.default_rng(0))
    assert torch.equal(turned[:, 0], turned[:, 1])  # the stacked frames warped alike
    distance, direction = _spot_polar(turned)
    assert np.allclose(distance, 15, atol=0.1)  # a turn: the same distance from the centre
    assert -30 <= direction.min() < -25 and 25 < direction.max() <= 30  # every angle up to 30 degrees either way

    scaled = _warped(images, 0, 0.25, np.random.default_rng(0))
    distance, direction = _spot_polar(scaled)
    assert np.allclose(direction, 0, atol=0.01)  # a scaling about the centre: the same direction
    assert 15 / 1.25 - 0.1 < distance.min() < 12.5 and 19.5 < distance.max() < 15 / 0.75 + 0.1
    assert _warped(images, 0, 0, np.random.default_rng(0)) is images


@pytest.fixture(scope="module")
def teacher(tmp_path_factory):
    """A state-only Goalie policy file: a few hundred PPO steps make a teacher good enough to imitate."""
    out = tmp_path_factory.mktemp("teacher")
    result = CliRunner().invoke(
        main,
        [
            "train",
            "Goalie-v0",
            "--state-only",
            "--steps",
            "256",
            "--envs",
            "1",
            "--eval-every",
            "256",
            "--eval-episodes",
            "1",
            "--final-episodes",
            "1",
            "--set",
            "n_steps=128",
            "--set",
            "batch_size=64",
            "--out",
            str(out),
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    return next((out / "Goalie-v0").iterdir()) / "best_model.safetensors"


@pytest.mark.slow
@pytest.mark.blender
def test_distill_writes_a_run_that_eval_replays(teacher, tmp_path):
    result = CliRunner().invoke(
        main,
        [
            "distill",
            "Goalie-v0",
            "--teacher",
            str(teacher),
            "--rounds",
            "2",
            "--episodes",
            "2",
            "--eval-episodes",
            "1",
            "--final-episodes",
            "2",
            "--frame-stack",
            "2",
            "--out",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    run = next((tmp_path / "Goalie-v0").iterdir())
    with (run / "rounds.csv").open() as f:
        rounds = list(csv.DictReader(f))
    assert [r["round"] for r in rounds] == ["0", "1"]
    assert 0 < int(rounds[0]["frames"]) < int(rounds[1]["frames"])  # each round adds the frames it rolled out
    config = json.loads((run / "config.json").read_text())
    assert config["config"]["algo"] == "dagger" and config["config"]["frame_stack"] == 2
    assert config["teacher"]["sha256"] == hashlib.sha256(teacher.read_bytes()).hexdigest()
    meta = json.loads((run / "best_model.json").read_text())
    assert meta["algorithm"] == "dagger" and meta["frame_stack"] == 2 and meta["observation_space"]["shape"][0] == 2
    results = json.loads((run / "results.json").read_text())
    assert (
        results["episodes"] == 2
        and results["frames"] == int(rounds[1]["frames"])
        and results["model"] == "best_model.safetensors"
    )
    replay = CliRunner().invoke(main, ["eval", "Goalie-v0", "--model", str(run / "best_model.safetensors")])
    assert replay.exit_code == 0 and "reproduces its run's results.json" in replay.output, replay.output
    # a second segment starts from the first's student, which acts from its first round on
    again = CliRunner().invoke(
        main,
        [
            "distill",
            "Goalie-v0",
            "--teacher",
            str(teacher),
            "--student",
            str(run / "best_model.safetensors"),
            "--rounds",
            "1",
            "--episodes",
            "1",
            "--mixing",
            "0.5",
            "--eval-episodes",
            "1",
            "--final-episodes",
            "1",
            "--frame-stack",
            "2",
            "--distractions",
            "{difficulty: [0.1, 0.3], camera: false}",
            "--state-loss",
            "0.5",
            "--consistency",
            "0.5",
            "--out",
            str(tmp_path / "again"),
        ],
    )
    assert again.exit_code == 0 and "(the teacher's share 50%)" in again.output, again.output
    second = next((tmp_path / "again" / "Goalie-v0").iterdir())
    recorded = json.loads((second / "config.json").read_text())["config"]
    assert recorded["distractions"] == {"difficulty": [0.1, 0.3], "camera": False} and recorded["state_loss"] == 0.5
    assert recorded["consistency"] == 0.5  # its clean twins rendered by a second env, which replayed each episode
    assert (
        json.loads((second / "config.json").read_text())["student"]["sha256"]
        == hashlib.sha256((run / "best_model.safetensors").read_bytes()).hexdigest()
    )
    refused = CliRunner().invoke(
        main,
        [
            "distill",
            "Goalie-v0",
            "--teacher",
            str(teacher),
            "--student",
            str(run / "best_model.safetensors"),
            "--out",
            str(tmp_path / "refused"),
        ],
    )  # frame stack 3 by default: the student sees 2
    assert (
        refused.exit_code != 0
        and "the student to start from sees" in refused.output
        and "Traceback" not in refused.output
    ), refused.output
    assert not (tmp_path / "refused" / "Goalie-v0").exists()
    # a student with DrQ's encoder: recorded in config.json and the policy file, which eval replays
    drq = CliRunner().invoke(
        main,
        [
            "distill",
            "Goalie-v0",
            "--teacher",
            str(teacher),
            "--encoder",
            "drq",
            *("--rounds", "1", "--episodes", "1", "--eval-episodes", "1", "--final-episodes", "1"),
            *("--frame-stack", "2", "--out", str(tmp_path / "drq"), "--no-progress"),
        ],
    )
    assert drq.exit_code == 0 and "round 0: " in drq.output, drq.output  # without the bar, a line per round
    third = next((tmp_path / "drq" / "Goalie-v0").iterdir())
    assert json.loads((third / "config.json").read_text())["config"]["encoder"] == "drq"
    assert "DrQEncoder" in (third / "best_model.json").read_text()
    replay = CliRunner().invoke(main, ["eval", "Goalie-v0", "--model", str(third / "best_model.safetensors")])
    assert replay.exit_code == 0 and "reproduces its run's results.json" in replay.output, replay.output


def test_a_teacher_of_another_env_is_refused_before_anything_runs(teacher, tmp_path):
    result = CliRunner().invoke(main, ["distill", "Hover2D-v0", "--teacher", str(teacher), "--out", str(tmp_path)])
    assert result.exit_code != 0 and "Traceback" not in result.output
    assert "the teacher acts on observations of shape (4,)" in result.output and "have shape (6,)" in result.output, (
        result.output
    )
    assert not (tmp_path / "Hover2D-v0").exists()


BAD_LEVELS = ("0.4:0.1", "hardest", "0.1:2")


@pytest.mark.parametrize(
    "given, message",
    [
        *[(given, "expected a difficulty from 0 to 1, easy, medium, hard, a range LOW:HIGH") for given in BAD_LEVELS],
        ("{difficulty: 0.1, background: {video: x}}", "distractions.background.video: unknown key 'video'"),
    ],
)
def test_a_bad_distractions_option_is_refused_before_anything_runs(teacher, tmp_path, given, message):
    result = CliRunner().invoke(
        main, ["distill", "Goalie-v0", "--teacher", str(teacher), "--distractions", given, "--out", str(tmp_path)]
    )
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    assert message in result.output, result.output
    assert not (tmp_path / "Goalie-v0").exists()


def test_rounds_whose_frames_cannot_fit_in_memory_are_refused_before_anything_runs(teacher, tmp_path):
    result = CliRunner().invoke(
        main, ["distill", "Goalie-v0", "--teacher", str(teacher), "--episodes", "1000000000", "--out", str(tmp_path)]
    )
    assert result.exit_code != 0 and "Traceback" not in result.output, result.output
    assert "GiB of frames, and" in result.output and "set --episodes" in result.output, result.output
    assert not (tmp_path / "Goalie-v0").exists()


def test_the_consistency_loss_without_distractions_is_refused_before_anything_runs(teacher, tmp_path):
    result = CliRunner().invoke(
        main, ["distill", "Goalie-v0", "--teacher", str(teacher), "--consistency", "1", "--out", str(tmp_path)]
    )
    assert result.exit_code != 0 and "Traceback" not in result.output, result.output
    assert "give --distractions too" in result.output, result.output
    assert not (tmp_path / "Goalie-v0").exists()
