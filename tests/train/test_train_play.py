"""Smoke runs of `visualenv train` and `visualenv play` with real rendering (tiny budgets)."""

import json
import re
import shutil

import imageio.v3 as iio
import numpy as np
import pytest
from click.testing import CliRunner

from visualenv.cli import main
from visualenv.errors import SpecError
from visualenv.train.evaluation import final_seed, seed_purpose, selection_seed

pytestmark = [pytest.mark.blender, pytest.mark.slow]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    result = CliRunner().invoke(
        main,
        [
            "train",
            "Goalie-v0",
            "--steps",
            "256",
            "--envs",
            "2",
            "--eval-every",
            "128",
            "--eval-episodes",
            "2",
            "--final-episodes",
            "2",
            "--set",
            "n_steps=64",
            "--set",
            "batch_size=64",
            "--set",
            "learning_rate=lin_3e-4",
            "--out",
            str(out),
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    runs = list((out / "Goalie-v0").iterdir())
    assert len(runs) == 1
    return runs[0]


def test_train_writes_a_complete_run_folder(run_dir):
    for name in [
        "config.json",
        "results.json",
        "best_model.zip",
        "final_model.zip",
        "checkpoints/latest/weights.safetensors",  # the training state as data, for --resume
        "checkpoints/latest/state.json",
        "best_model.safetensors",
        "best_model.json",
        "final_model.safetensors",
        "final_model.json",
        "evaluations.npz",
        "logs/progress.csv",
        "plots/rewards.png",
        "plots/lengths.png",
        "plots/success.png",
        "plots/fps.png",
    ]:
        assert (run_dir / name).is_file(), name
    results = json.loads((run_dir / "results.json").read_text())
    assert results["episodes"] == 2 and results["steps"] >= 256
    assert results["model"] == "best_model.safetensors"  # the final evaluation read the policy file: no pickle
    assert -10 <= results["mean_reward"] <= 10 and 0 <= results["success_rate"] <= 1
    assert 15 <= results["mean_length"] <= 60  # Goalie episodes end when the ball crosses (~21 steps)
    config = json.loads((run_dir / "config.json").read_text())
    assert config["config"]["hyperparams"] == {"n_steps": 64, "batch_size": 64, "learning_rate": "lin_3e-4"}
    assert list(iio.imread(run_dir / "plots" / "rewards.png").shape[2:]) in ([3], [4])


FIGURES = (
    "episodes",
    "mean_reward",
    "std_reward",
    "mean_length",
    "success_rate",
    "reward_ci95",
    "length_ci95",
    "success_ci95",
    "eval_seed",
)


def test_selection_and_final_evaluation_use_disjoint_seeds(run_dir):
    """The SB3 backend picks its best model on one stream and reports on another; results.json records both."""
    results = json.loads((run_dir / "results.json").read_text())
    selection = results["selection"]
    assert selection["eval_seed"] == selection_seed(0) and results["eval_seed"] == final_seed(0)
    assert seed_purpose(selection["eval_seed"]) == "selection" and seed_purpose(results["eval_seed"]) == "final"
    assert selection["evaluations"] >= 1 and selection["episodes"] == 2 and selection["best_at_step"] >= 128


def test_eval_replays_the_runs_final_evaluation(run_dir, tmp_path):
    recorded = json.loads((run_dir / "results.json").read_text())
    assert recorded["eval_seed"] == final_seed(0)  # the run's seed 0 in the final evaluation's band
    out = tmp_path / "eval.json"
    result = CliRunner().invoke(
        main, ["eval", "Goalie-v0", "--model", str(run_dir / "best_model.safetensors"), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert (
        f"2 deterministic episodes, the first reset with seed {final_seed(0)}" in result.output
    )  # the run's count and seed by default
    assert (
        "(bootstrap)" in result.output
        and "(Wilson)" in result.output
        and "reproduces its run's results.json" in result.output
    )
    figures = json.loads(out.read_text())
    assert {k: figures[k] for k in FIGURES} == {k: recorded[k] for k in FIGURES} and figures[
        "matches_results_json"
    ] is True


def test_eval_that_differs_on_a_like_machine_reports_it_without_excuse(run_dir, tmp_path):
    """A replay that differs on a like machine is reported as a difference: rendering is deterministic there, so no
    tolerance and no sample check soften it (docs/testing.md, 'Deterministic rendering')."""
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    recorded = json.loads((copy / "results.json").read_text())
    recorded["mean_reward"] += 1.0
    (copy / "results.json").write_text(json.dumps(recorded))
    result = CliRunner().invoke(main, ["eval", "Goalie-v0", "--model", str(copy / "best_model.safetensors")])
    assert result.exit_code == 0, result.output
    assert "differs from its run's results.json: mean_reward" in result.output
    assert "within that tolerance" not in result.output and "as a sample of" not in result.output, result.output


def test_eval_of_a_model_alone_and_its_refusals(run_dir, tmp_path):
    import shutil

    alone = tmp_path / "goalie.safetensors"  # no config.json beside it: the frame stack comes from the model
    shutil.copy(run_dir / "best_model.safetensors", alone)
    shutil.copy(run_dir / "best_model.json", alone.with_suffix(".json"))
    result = CliRunner().invoke(main, ["eval", "Goalie-v0", "--model", str(alone), "--episodes", "3", "--seed", "5"])
    assert result.exit_code == 0, result.output
    assert (
        "3 deterministic episodes, the first reset with seed 5" in result.output and "results.json" not in result.output
    )
    missing = CliRunner().invoke(main, ["eval", "Goalie-v0", "--model", str(tmp_path / "none.zip")])
    assert missing.exit_code == 2 and "none.zip: no such file (or 'pretrained' for the shipped agent)" in missing.output
    never = tmp_path / "figures" / "never.json"  # checked writable first, and not left behind empty by the refusal
    other_env = CliRunner().invoke(main, ["eval", "Hover2D-v0", "--model", str(alone), "-o", str(never)])
    assert (
        other_env.exit_code == 1
        and "was trained on observations (4, 100, 100) and actions Discrete(2)" in other_env.output
    )
    assert never.parent.is_dir() and not never.exists()
    unwritable = CliRunner().invoke(
        main, ["eval", "Goalie-v0", "--model", str(alone), "-o", str(alone.with_suffix(".json") / "eval.json")]
    )
    assert unwritable.exit_code == 2 and "cannot write" in unwritable.output
    not_shipped = CliRunner().invoke(
        main, ["play", multi_camera_cartpole(tmp_path, "[48, 48]"), "--model", "pretrained"]
    )
    assert not_shipped.exit_code == 1 and "no shipped model for MultiCart-v0" in not_shipped.output


def test_linear_schedule_lowers_the_learning_rate_over_the_run(run_dir):
    from visualenv.train.plots import read_progress

    rates = read_progress(run_dir)["train/learning_rate"]
    rates = rates[~np.isnan(rates)]
    # the first update comes after 128 of the run's 256 steps: lin_3e-4 is half way down (a constant would log 3e-4)
    assert rates[0] == pytest.approx(1.5e-4)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--set", "lerning_rate=1e-4"], "PPO has no hyperparameter 'lerning_rate' (did you mean 'learning_rate'?"),
        (["--set", "learning_rate=fast"], "expected a number or a linear schedule such as lin_3e-4"),
        (["--set", "n_steps=abc"], "n_steps: expected a number (default 2048), got 'abc'"),
        (
            ["--algo", "dqn", "--set", "clip_range=0.2"],
            "DQN has no hyperparameter 'clip_range' (names: learning_rate, buffer_size",
        ),
    ],
)
def test_bad_hyperparameters_fail_before_anything_starts(tmp_path, args, message):
    result = CliRunner().invoke(
        main, ["train", "Goalie-v0", "--steps", "64", "--no-progress", "--out", str(tmp_path / "runs"), *args]
    )
    assert result.exit_code == 1 and message in result.output and "Traceback" not in result.output
    assert not (tmp_path / "runs").exists()  # no empty run folder left behind


def test_devices_are_checked_before_anything_starts(tmp_path):
    """--device cuda where torch sees no GPU, and sb3's device options with --backend rllib, fail before a run folder;
    --render-device reaches the training envs' renderer options."""
    import torch

    from visualenv.train.sb3 import TrainConfig, _vec_kwargs

    out = tmp_path / "runs"
    if not torch.cuda.is_available():
        result = CliRunner().invoke(
            main, ["train", "Goalie-v0", "--device", "cuda", "--no-progress", "--out", str(out)]
        )
        assert result.exit_code == 1 and "sees no CUDA device" in result.output and "Traceback" not in result.output
    result = CliRunner().invoke(main, ["train", "Goalie-v0", "--device", "gpu", "--no-progress", "--out", str(out)])
    assert (
        result.exit_code == 1
        and "expected auto, cpu, cuda or cuda:N" in result.output
        and "Traceback" not in result.output
    )
    result = CliRunner().invoke(
        main, ["train", "Goalie-v0", "--device", "cuda", "--set", "device=cpu", "--out", str(out)]
    )
    assert result.exit_code != 0 and "set device 'cpu' as well" in result.output
    result = CliRunner().invoke(
        main, ["train", "Goalie-v0", "--backend", "rllib", "--render-device", "gpu", "--out", str(out)]
    )
    assert result.exit_code != 0 and "--render-device: not for --backend rllib" in result.output
    assert not out.exists()
    assert _vec_kwargs(TrainConfig(spec="Goalie-v0", render_device="gpu")) == {"device": "gpu"}
    assert _vec_kwargs(TrainConfig(spec="Goalie-v0")) == {}


def test_a_config_files_exponent_numbers_are_numbers(tmp_path):
    """YAML 1.1 reads 3e-4 as text; --config reads it as the number --set reads (here n_steps is the one refused)."""
    config = tmp_path / "hyper.yaml"
    config.write_text("learning_rate: 3e-4\nn_steps: abc\n")
    result = CliRunner().invoke(
        main, ["train", "Goalie-v0", "--config", str(config), "--steps", "64", "--out", str(tmp_path / "runs")]
    )
    assert (
        result.exit_code == 1 and "n_steps: expected a number" in result.output and "learning_rate" not in result.output
    ), result.output


def test_config_file_must_be_a_mapping(tmp_path):
    bad = tmp_path / "hyper.yaml"
    bad.write_text("- learning_rate: 1e-4\n")
    result = CliRunner().invoke(main, ["train", "Goalie-v0", "--config", str(bad), "--out", str(tmp_path / "runs")])
    assert result.exit_code == 2 and "expected a mapping of hyperparameters" in result.output
    bad.write_text("learning_rate: [1e-4\n")
    result = CliRunner().invoke(main, ["train", "Goalie-v0", "--config", str(bad), "--out", str(tmp_path / "runs")])
    assert result.exit_code == 2 and "is not YAML" in result.output


def test_algorithm_kwargs_makes_schedules_callable():
    from visualenv.train.sb3 import algorithm_kwargs

    kwargs = algorithm_kwargs("ppo", {"learning_rate": "lin_1e-3", "clip_range": 0.2, "n_steps": 64})
    assert kwargs["learning_rate"](1.0) == pytest.approx(1e-3) and kwargs["learning_rate"](0.25) == pytest.approx(
        2.5e-4
    )
    assert kwargs["clip_range"] == 0.2 and kwargs["n_steps"] == 64


def test_train_resumes_from_the_latest_checkpoint_and_keeps_the_history(run_dir, tmp_path):
    run_dir = shutil.copytree(
        run_dir, tmp_path / "run"
    )  # a copy: the shared run stays as trained, whatever order the tests run in
    before = np.load(run_dir / "evaluations.npz")["timesteps"].tolist()
    rows_before = len((run_dir / "logs" / "progress.csv").read_text().splitlines())
    refused = CliRunner().invoke(main, ["train", "Goalie-v0", "--resume", str(run_dir), "--envs", "3"])
    assert refused.exit_code == 2 and "--envs: a resumed run keeps its settings" in refused.output
    result = CliRunner().invoke(
        main,
        ["train", "Goalie-v0", "--resume", str(run_dir), "--steps", "384", "--no-progress", "--set", "ent_coef=0.02"],
    )
    assert result.exit_code == 0, result.output
    config = json.loads((run_dir / "config.json").read_text())
    assert config["config"]["hyperparams"] == {
        "n_steps": 64,
        "batch_size": 64,
        "learning_rate": "lin_3e-4",
        "ent_coef": 0.02,
    }
    assert config["resumes"][-1]["hyperparams"] == {"ent_coef": 0.02} and config["resumes"][-1]["command"]
    from stable_baselines3 import PPO

    assert PPO.load(run_dir / "final_model.zip").ent_coef == 0.02  # the change reached the model
    results = json.loads((run_dir / "results.json").read_text())
    assert results["steps"] >= 384 and results["stopped_early"] is False
    after = np.load(run_dir / "evaluations.npz")["timesteps"].tolist()
    assert after[: len(before)] == before and len(after) > len(before)  # earlier evaluations kept, new ones added
    assert len((run_dir / "logs" / "progress-1.csv").read_text().splitlines()) == rows_before  # the first segment, kept
    from visualenv.train.plots import read_progress

    steps = read_progress(run_dir)["time/total_timesteps"]
    assert steps[0] < 256 < steps[-1]  # the plots see both segments


def test_play_with_the_trained_model_records_a_gif(run_dir, tmp_path):
    """The run's own zip, a pickle, plays when trusted (--trust-pickle)."""
    gif = tmp_path / "play.gif"
    result = CliRunner().invoke(
        main,
        [
            "play",
            "Goalie-v0",
            "--model",
            str(run_dir / "best_model.zip"),
            "--trust-pickle",
            "--episodes",
            "1",
            "--record",
            str(gif),
            "--view",
            "fast",
            "--view-size",
            "200",
        ],
    )
    assert result.exit_code == 0, result.output
    episode = re.search(r"episode 0: return (-?\d+\.\d\d), length (\d+), (success|no success) \((\w+)\)", result.output)
    assert episode, result.output
    assert (episode[3], episode[4]) in (("success", "caught"), ("no success", "scored"), ("no success", "left_goal")), (
        result.output
    )
    length = int(episode[2])
    frames = iio.imread(gif)
    assert frames.ndim == 4 and frames.shape[0] in (length, length + 1) and length >= 10  # one frame per step
    assert (
        frames.shape[1] == 200 and frames.shape[2] == 200 + 4 + 200
    )  # the 100 px observation scaled 2x, a gap, the 200 px view
    # the view beside the observation: the frames change as the ball rolls
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 0.5


def test_a_policy_file_plays_like_its_model(run_dir, tmp_path):
    """export-policy keeps the policy (half precision) and drops the optimizer: the shipped agents' format."""
    import torch
    from safetensors import safe_open
    from stable_baselines3 import PPO

    from visualenv.train.model_files import load_model

    policy_file = tmp_path / "policy.safetensors"
    exported = CliRunner().invoke(
        main, ["export-policy", "--trust-pickle", str(run_dir / "best_model.zip"), str(policy_file)]
    )
    assert exported.exit_code == 0, exported.output
    with safe_open(str(policy_file), "pt") as f:  # the weights alone: no optimizer state
        assert {f.get_tensor(name).dtype for name in f.keys()} == {torch.float16} and not [
            n for n in f.keys() if "optimizer" in n
        ]
    meta = json.loads(policy_file.with_suffix(".json").read_text())
    assert (
        meta["algorithm"] == "ppo" and meta["frame_stack"] == 4 and meta["spec"]["id"] == "Goalie-v0"
    )  # from the run's config.json
    assert policy_file.stat().st_size < (run_dir / "best_model.zip").stat().st_size / 1.5
    model = PPO.load(run_dir / "best_model.zip", device="cpu")
    policy = load_model(policy_file)
    obs = torch.as_tensor(
        np.random.default_rng(0).integers(0, 256, (16, *model.observation_space.shape)), dtype=torch.float32
    )
    with torch.no_grad():
        want = torch.cat([model.policy.get_distribution(obs).distribution.probs, model.policy.predict_values(obs)], 1)
        got = torch.cat([policy.get_distribution(obs).distribution.probs, policy.predict_values(obs)], 1)
        exact = load_model(
            run_dir / "best_model.safetensors"
        )  # train's own policy file: float32, the zip's policy exactly
        assert torch.equal(
            want, torch.cat([exact.get_distribution(obs).distribution.probs, exact.predict_values(obs)], 1)
        )
    assert want[:, -1].std() > 1e-3  # the values differ between observations: the comparison below is not of constants
    assert torch.allclose(want, got, atol=1e-2, rtol=1e-2)
    webp = tmp_path / "play.webp"
    played = CliRunner().invoke(
        main,
        [
            "play",
            "Goalie-v0",
            "--model",
            str(policy_file),
            "--episodes",
            "1",
            "--record",
            str(webp),
            "--view",
            "fast",
            "--view-size",
            "200",
        ],
    )
    assert played.exit_code == 0, played.output
    frames = iio.imread(webp, index=...)[
        ..., :3
    ]  # every frame (imageio reads one by default), without the alpha channel
    assert frames.ndim == 4 and frames.shape[0] >= 10 and frames.shape[1:3] == (200, 200 + 4 + 200)
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 0.5
    not_a_policy = CliRunner().invoke(
        main, ["play", "Goalie-v0", "--model", str(run_dir / "config.json"), "--episodes", "1"]
    )
    assert not_a_policy.exit_code == 1 and "not a policy file of visualenv" in not_a_policy.output


def test_play_refuses_what_it_cannot_do_before_playing(run_dir, tmp_path):
    model = str(run_dir / "best_model.safetensors")
    wrong_format = CliRunner().invoke(
        main, ["play", "Goalie-v0", "--episodes", "1", "--record", str(tmp_path / "play.avi")]
    )
    assert wrong_format.exit_code == 2 and "expected a file ending in .gif or .webp or .mp4" in wrong_format.output
    other_env = CliRunner().invoke(main, ["play", "Hover2D-v0", "--model", model, "--episodes", "1"])
    assert (
        other_env.exit_code == 1
        and "was trained on observations (4, 100, 100) and actions Discrete(2)" in other_env.output
    )
    assert "actions Discrete(4)" in other_env.output  # Hover2D's four pulses
    junk = tmp_path / "junk.zip"
    junk.write_text("not a model")
    refused = CliRunner().invoke(main, ["play", "Goalie-v0", "--model", str(junk), "--episodes", "1"])
    assert refused.exit_code == 1 and f"{junk} is an SB3 model: a pickle-based file" in refused.output
    not_a_model = CliRunner().invoke(
        main, ["play", "Goalie-v0", "--model", str(junk), "--episodes", "1", "--trust-pickle"]
    )
    assert not_a_model.exit_code == 1 and f"cannot load {junk} as a PPO model" in not_a_model.output
    for result in (other_env, refused, not_a_model):
        assert isinstance(result.exception, SystemExit)  # an error line and an exit code, not an escaped exception


def test_resume_needs_a_run_folder(tmp_path):
    result = CliRunner().invoke(main, ["train", "Goalie-v0", "--resume", str(tmp_path)])
    assert result.exit_code == 2 and "is not a run folder of `visualenv train`" in result.output


def multi_camera_cartpole(tmp_path, side: str) -> str:
    """VisualCartPole with a Dict observation: the usual grayscale camera and a small RGB one."""
    from visualenv.env.registration import resolve

    text = (
        resolve("VisualCartPole-v0")
        .read_text()
        .replace("id: VisualCartPole-v0", "id: MultiCart-v0")
        .replace(
            "  camera: Camera\n  resolution: [100, 100]\n  color: grayscale\n",
            f"  cameras:\n    front: {{camera: Camera, resolution: [64, 64]}}\n    side: {{camera: Camera, resolution: {side}, color: rgb}}\n",
        )
    )
    assert "cameras:" in text
    path = tmp_path / "multi.yaml"
    path.write_text(text)
    return str(path)


def test_multi_camera_specs_train_and_play(tmp_path):
    spec = multi_camera_cartpole(tmp_path, "[40, 40]")
    out = tmp_path / "runs"
    result = CliRunner().invoke(
        main,
        [
            "train",
            spec,
            "--steps",
            "64",
            "--envs",
            "2",
            "--eval-every",
            "64",
            "--eval-episodes",
            "1",
            "--final-episodes",
            "1",
            "--set",
            "n_steps=32",
            "--set",
            "batch_size=32",
            "--out",
            str(out),
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    (run,) = (out / "MultiCart-v0").iterdir()
    from stable_baselines3 import PPO

    model = PPO.load(run / "best_model.zip")
    assert type(model.policy).__name__ == "MultiInputActorCriticPolicy"
    assert {k: s.shape for k, s in model.observation_space.spaces.items()} == {
        "front": (4, 64, 64),
        "side": (12, 40, 40),
    }
    gif = tmp_path / "play.gif"
    played = CliRunner().invoke(
        main,
        [
            "play",
            spec,
            "--model",
            str(run / "best_model.safetensors"),
            "--episodes",
            "1",
            "--record",
            str(gif),
            "--view",
            "fast",
            "--view-size",
            "64",
        ],
    )
    assert played.exit_code == 0, played.output
    frame = iio.imread(gif)[0]
    assert frame.shape[1] == 64 + 4 + 40 + 4 + 64  # both cameras' newest frames and the 64 px view, with gaps
    side = frame[:40, 64 + 4 : 64 + 4 + 40].astype(int)
    assert (
        side[..., 0] - side[..., 2] > 40
    ).any()  # the red cart in colour: the newest RGB frame, not one channel of the stack


def test_images_too_small_for_the_cnn_are_located_before_anything_starts(tmp_path):
    spec = multi_camera_cartpole(tmp_path, "[32, 24]")
    result = CliRunner().invoke(main, ["train", spec, "--steps", "64", "--out", str(tmp_path / "runs")])
    assert result.exit_code == 2, result.output
    assert (
        "multi.yaml:" in result.output
        and "observation.cameras.side.resolution: 32x24 is too small for the CNN policy" in result.output
    )
    assert not (tmp_path / "runs").exists()


def test_images_too_small_for_drqs_encoder_are_located_and_larger_ones_pass_its_check(tmp_path):
    """DrQ's encoder takes images down to 15x15 (NatureCNN 36): a config that names it is checked by its own size."""
    from visualenv.spec import load_spec
    from visualenv.train.encoders import DrQEncoder
    from visualenv.train.config_checks import check_cnn_input

    drq = 'policy_kwargs={"features_extractor_class": "visualenv.train.encoders.DrQEncoder"}'
    spec = multi_camera_cartpole(tmp_path, "[12, 20]")
    out = tmp_path / "runs"
    result = CliRunner().invoke(main, ["train", spec, "--algo", "sac", "--set", drq, "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert "observation.cameras.side.resolution: 12x20 is too small for the CNN policy" in result.output
    assert "(DrQEncoder): it needs at least 15x15" in result.output and "front" not in result.output
    assert not out.exists()
    larger = load_spec(multi_camera_cartpole(tmp_path, "[24, 20]"))
    check_cnn_input(larger, {"features_extractor_class": DrQEncoder})  # passes: NatureCNN's check refuses it
    with pytest.raises(SpecError, match="20 is too small for the CNN policy of `visualenv train` .SB3's NatureCNN."):
        check_cnn_input(larger, None)


def test_state_only_training_runs_without_warnings(tmp_path):
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = CliRunner().invoke(
            main,
            [
                "train",
                "Goalie-v0",
                "--state-only",
                "--steps",
                "256",
                "--envs",
                "2",
                "--eval-every",
                "128",
                "--eval-episodes",
                "2",
                "--final-episodes",
                "2",
                "--set",
                "n_steps=64",
                "--set",
                "batch_size=64",
                "--out",
                str(tmp_path),
                "--no-progress",
            ],
        )
    assert result.exit_code == 0, result.output
    summary = re.search(
        r"best model over 2 episodes: reward (-?\d+\.\d\d) \+- \d+\.\d\d, length (\d+\.\d), success (\d+) %",
        result.output,
    )
    assert summary and -10 <= float(summary[1]) <= 10 and int(summary[3]) in (0, 50, 100), result.output
    assert not [w for w in caught if "not of the same type" in str(w.message)]
    run = next((tmp_path / "Goalie-v0").iterdir())
    assert json.loads((run / "config.json").read_text())["config"]["render"] is False
    # --no-progress: one line per evaluation (a log file shows the run's course); the monitor files name the env
    lines = re.findall(
        r"^eval at (\d+) steps: mean return -?\d+\.\d\d \+- \d+\.\d\d over 2 episodes, success \d/2$",
        result.output,
        re.M,
    )
    assert [int(s) for s in lines] == [128, 256], result.output
    assert '"env_id": "visualenv/Goalie-v0"' in (run / "monitor" / "0.monitor.csv").read_text().splitlines()[0]


def test_play_random_policy():
    result = CliRunner().invoke(main, ["play", "Goalie-v0", "--episodes", "2"])
    assert result.exit_code == 0, result.output
    assert result.output.count("episode ") == 2 and "mean return" in result.output


def test_sigterm_stops_training_and_still_evaluates(tmp_path):
    import signal
    import subprocess
    import sys
    import time

    command = [
        sys.executable,
        "-m",
        "visualenv.cli",
        "train",
        "Goalie-v0",
        "--steps",
        "100000",
        "--envs",
        "2",
        "--eval-every",
        "128",
        "--eval-episodes",
        "1",
        "--final-episodes",
        "2",
        "--set",
        "n_steps=64",
        "--set",
        "batch_size=64",
        "--out",
        str(tmp_path),
        "--no-progress",
    ]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 240
        while not list(tmp_path.glob("Goalie-v0/*/evaluations.npz")) and time.monotonic() < deadline:
            time.sleep(0.5)
        process.send_signal(signal.SIGTERM)
        output, _ = process.communicate(timeout=240)
    finally:
        process.kill()
    assert process.returncode == 0, output
    assert "stopped early" in output
    (run,) = tmp_path.glob("Goalie-v0/*")
    results = json.loads((run / "results.json").read_text())
    assert results["stopped_early"] is True and results["episodes"] == 2 and results["steps"] < 100000
    assert (run / "plots" / "rewards.png").is_file()


def test_an_image_replay_buffer_that_cannot_fit_is_refused_before_any_env_starts(tmp_path):
    """SB3's default buffer (a million samples) of 4 stacked 100x100 frames, twice (obs and next obs), is 75 GiB."""
    from visualenv.env.registration import resolve
    from visualenv.spec import load_spec
    from visualenv.train.config_checks import replay_buffer_bytes
    from visualenv.train.sb3 import TrainConfig

    result = CliRunner().invoke(
        main, ["train", "LunarLanding-v0", "--algo", "sac", "--steps", "64", "--out", str(tmp_path / "runs")]
    )
    assert (
        result.exit_code != 0
        and "SAC's replay buffer would take 74.5 GiB" in result.output
        and "optimize_memory_usage" in result.output
    )
    assert not (tmp_path / "runs").exists()
    loaded = load_spec(resolve("LunarLanding-v0"))
    sac = TrainConfig("LunarLanding-v0", algo="sac")
    assert (
        replay_buffer_bytes(sac, {"buffer_size": 50_000, "optimize_memory_usage": True}, loaded)
        == 50_000 * 4 * 100 * 100
    )
    assert (
        replay_buffer_bytes(TrainConfig("LunarLanding-v0", algo="sac", render=False), {"buffer_size": 1000}, loaded)
        == 1000 * 6 * 4 * 2
    )
    assert replay_buffer_bytes(TrainConfig("LunarLanding-v0", algo="ppo"), {}, loaded) is None  # on-policy: no buffer


def test_sac_trains_a_continuous_action_env(tmp_path):
    result = CliRunner().invoke(
        main,
        [
            "train",
            "LunarLanding-v0",
            "--algo",
            "sac",
            "--state-only",
            "--steps",
            "200",
            "--envs",
            "1",
            "--eval-every",
            "100",
            "--eval-episodes",
            "2",
            "--final-episodes",
            "2",
            "--set",
            "learning_starts=100",
            "--set",
            "train_freq=4",
            "--set",
            "buffer_size=1000",
            "--out",
            str(tmp_path),
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    run = next((tmp_path / "LunarLanding-v0").iterdir())
    assert json.loads((run / "config.json").read_text())["config"]["algo"] == "sac"
    assert json.loads((run / "results.json").read_text())["episodes"] == 2
    evaluated = CliRunner().invoke(
        main, ["eval", "LunarLanding-v0", "--model", str(run / "best_model.safetensors"), "--episodes", "2"]
    )
    assert evaluated.exit_code == 0 and "reproduces" in evaluated.output, evaluated.output
