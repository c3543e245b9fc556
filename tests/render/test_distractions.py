"""Distractions (docs/distractions.md): the observation's camera and colours change per episode, nothing else does.

Rendered with real Blender: the state, rewards and random streams of a distracted env are those of the plain env,
its pixels differ from the plain env's more at higher difficulty, each kind changes what it says, a seed draws the
same distractions again, and each tile of a batch is its env distracted alone.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import yaml

import visualenv
from visualenv.env.batch import BatchedVectorEnv
from visualenv.errors import SpecError

pytestmark = pytest.mark.blender

ROOT = Path(__file__).resolve().parents[2]
CARTPOLE = ROOT / "specs" / "dmc" / "cartpole_swingup.yaml"
#: the Distracting Control Suite's difficulties
LEVELS = (0.1, 0.2, 0.3)


def segmented_cartpole(folder: Path, distractions: dict | None = None) -> Path:
    """DMC-cartpole-swingup-v0 with a segmentation camera beside its colour one (its model path made absolute)."""
    data = yaml.safe_load(CARTPOLE.read_text(encoding="utf-8"))
    data["physics"]["model"] = str((CARTPOLE.parent / data["physics"]["model"]).resolve())
    view = data["observation"]
    data["observation"] = {"cameras": {"eye": view, "mask": {**view, "color": "segmentation"}}}
    data["action_repeat"] = 1
    if distractions is not None:
        data["distractions"] = distractions
    out = folder / "cartpole_segmented.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return out


def first_frames(target, seeds, **options) -> list:
    env = visualenv.make(target, **options)
    try:
        return [env.reset(seed=seed)[0] for seed in seeds]
    finally:
        env.close()


def mean_difference(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(int) - b.astype(int)).mean())


def test_distractions_leave_the_state_rewards_and_random_streams_unchanged() -> None:
    plain = visualenv.make("DMC-cartpole-swingup-v0", action_repeat=2)
    distracted = visualenv.make("DMC-cartpole-swingup-v0", action_repeat=2, distractions=0.3)
    try:
        a, _ = plain.reset(seed=7)
        b, _ = distracted.reset(seed=7)
        assert mean_difference(a, b) > 5  # the pixels do change
        actions = np.random.default_rng(0).uniform(-1, 1, size=(12, 1)).astype(np.float32)
        for action in actions:
            p, d = plain.step(action), distracted.step(action)
            assert p[1:4] == d[1:4]  # reward, terminated, truncated
            assert np.array_equal(plain.unwrapped.data.qpos, distracted.unwrapped.data.qpos)
            assert np.array_equal(plain.unwrapped.data.qvel, distracted.unwrapped.data.qvel)
        assert plain.unwrapped.np_random.random() == distracted.unwrapped.np_random.random()
    finally:
        plain.close()
        distracted.close()


def test_a_higher_difficulty_changes_the_pixels_more() -> None:
    seeds = range(4)
    clean = first_frames("DMC-cartpole-swingup-v0", seeds)
    distances = [
        np.mean(
            [
                mean_difference(c, f)
                for c, f in zip(clean, first_frames("DMC-cartpole-swingup-v0", seeds, distractions=level))
            ]
        )
        for level in LEVELS
    ]
    assert np.all(np.diff(distances) > 1.0) and distances[0] > 2.0, distances
    assert first_frames("DMC-cartpole-swingup-v0", [0], distractions=0)[0].tobytes() == clean[0].tobytes()


def test_each_kind_changes_what_it_says(tmp_path: Path) -> None:
    """Colours alone keep every pixel on its object (the segmentation is the plain env's) and change the colours;
    the camera alone moves the objects in the image; the background alone (the floor kept opaque: its alpha is
    checked below) changes the sky's pixels only."""
    spec = segmented_cartpole(tmp_path)
    (clean,) = first_frames(spec, [3])
    (colors,) = first_frames(spec, [3], distractions={"difficulty": 0.3, "camera": False, "background": False})
    (camera,) = first_frames(spec, [3], distractions={"difficulty": 0.3, "colors": False, "background": False})
    (backdrop,) = first_frames(
        spec, [3], distractions={"difficulty": 0.3, "colors": False, "camera": False, "floor_alpha": 1.0}
    )
    assert np.array_equal(colors["mask"], clean["mask"]) and mean_difference(colors["eye"], clean["eye"]) > 5
    assert (colors["mask"] != camera["mask"]).mean() > 0.05
    sky = clean["mask"][..., 0] == 0
    assert np.array_equal(backdrop["mask"], clean["mask"]) and sky.mean() > 0.2
    assert mean_difference(backdrop["eye"][sky], clean["eye"][sky]) > 10
    assert np.array_equal(backdrop["eye"][~sky], clean["eye"][~sky])  # the background lights nothing


def test_the_floor_at_the_suites_alpha_lets_the_sky_through(tmp_path: Path) -> None:
    """DMC cartpole's floor (its material 'grid') at the suite's alpha 0.3, under an opaque background (hard): its
    pixels move from the opaque floor's toward the sky seen through it (alpha 0), on average 0.3 x floor + 0.7 x sky
    in linear light (Cycles draws the transparency per sample: at the fast preset's one sample a pixel shows the
    floor or the sky, dithered); nothing else changes."""
    spec = segmented_cartpole(tmp_path)
    floor_only = {"difficulty": 0.3, "camera": False, "colors": False, "background": True}
    opaque, faded, through = (
        first_frames(spec, [3], distractions={**floor_only, "floor_alpha": alpha})[0] for alpha in (1.0, 0.3, 0.0)
    )
    mask = opaque["mask"][..., 0]
    floor = mask == mask[-1, mask.shape[1] // 2]  # the bottom of the level camera's view is floor
    assert floor.mean() > 0.2 and np.array_equal(faded["mask"], opaque["mask"])
    own, seen, sky = (linear(x["eye"][floor]).mean(axis=0) for x in (opaque, faded, through))
    apart = np.abs(own - sky).max()
    assert apart > 0.05  # the background seen through the floor differs from the floor
    assert np.abs(seen - sky).max() < np.abs(own - sky).max() - 0.3 * apart  # toward the sky
    assert np.abs(seen - (0.3 * own + 0.7 * sky)).max() < 0.1 * apart, (own, seen, sky)
    assert np.array_equal(faded["eye"][~floor], opaque["eye"][~floor])


def linear(pixels: np.ndarray) -> np.ndarray:
    """8-bit sRGB as linear light in [0, 1]."""
    x = pixels.astype(np.float64) / 255
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def test_a_seed_draws_the_same_distractions_and_dynamic_ones_drift(tmp_path: Path) -> None:
    env = visualenv.make("DMC-cartpole-swingup-v0", distractions=0.2)
    try:
        first, _ = env.reset(seed=11)
        other, _ = env.reset(seed=12)
        again, _ = env.reset(seed=11)
        assert first.tobytes() == again.tobytes() and mean_difference(first, other) > 2
        before = env.unwrapped._distractions.current
        env.step(np.zeros(1, np.float32))
        assert env.unwrapped._distractions.current == before  # fixed for the episode
    finally:
        env.close()
    spec = segmented_cartpole(tmp_path, {"difficulty": 0.3, "dynamic": True, "colors": False, "background": False})
    env = visualenv.make(spec)
    try:
        obs, _ = env.reset(seed=1)
        masks = [obs["mask"]]
        for _ in range(3):
            env.unwrapped.data.qvel[:] = 0  # a still cart and pole: what moves in the image is the camera
            masks.append(env.step(np.zeros(1, np.float32))[0]["mask"])
        assert all((a != b).any() for a, b in zip(masks, masks[1:]))
    finally:
        env.close()


def test_an_env_carries_its_distraction_through_pickle() -> None:
    env = visualenv.make("DMC-cartpole-swingup-v0", distractions=0.3)
    copy = None
    try:
        env.reset(seed=4)
        copy = pickle.loads(pickle.dumps(env))
        action = np.full(1, 0.5, np.float32)
        assert env.step(action)[0].tobytes() == copy.step(action)[0].tobytes()
    finally:
        env.close()
        if copy is not None:
            copy.close()


def test_any_spec_takes_them_and_the_spec_section_is_checked(tmp_path: Path) -> None:
    """A spec of the house's own scene (Goalie) is distracted the same way, and its background changes only the sky,
    though Goalie's world lights its field; a bad section names its line."""
    (clean,) = first_frames("Goalie-v0", [0])
    (moved,) = first_frames("Goalie-v0", [0], distractions=0.2)
    assert mean_difference(clean, moved) > 2
    (backdrop,) = first_frames("Goalie-v0", [0], distractions={"difficulty": 0.3, "camera": False, "colors": False})
    sky = (backdrop != clean).any(axis=-1)
    assert sky.mean() > 0.05 and np.array_equal(backdrop[20:], clean[20:]), sky.mean()  # rows 0-15 are the sky
    spec = tmp_path / "bad.yaml"
    text = CARTPOLE.read_text(encoding="utf-8").replace("model: assets/", f"model: {CARTPOLE.parent}/assets/")
    spec.write_text(text + "distractions: {difficulty: 2}\n", encoding="utf-8")
    with pytest.raises(SpecError) as caught:
        visualenv.make(spec)
    line = len(text.splitlines()) + 1
    assert f"bad.yaml:{line}:" in str(caught.value) and "distractions.difficulty" in str(caught.value), str(
        caught.value
    )


def agreement(a: np.ndarray, b: np.ndarray) -> float:
    """The share of pixels within 8 levels (what the batch tests hold a tile to against its env's own render)."""
    return float((np.abs(a.astype(int) - b.astype(int)) <= 8).mean())


def test_each_tile_of_a_batch_is_its_env_distracted_alone(tmp_path: Path) -> None:
    """Every kind at 0.2 in one batch render: each env's colour and segmentation tiles agree with the env alone (same
    seed, same actions; noise='shared', as a batch renders) on >= 98 % of pixels within 8 levels, every step; the
    state and rewards are those of the undistracted batch."""
    spec, n = segmented_cartpole(tmp_path), 3
    batch = visualenv.make_vec(spec, n, batched=True, distractions=0.2)
    plain = visualenv.make_vec(spec, n, batched=True, render=False)
    alone = [visualenv.make(spec, distractions=0.2, noise="shared") for _ in range(n)]
    try:
        tiles, _ = batch.reset(seed=7)
        plain.reset(seed=7)
        frames = [env.reset(seed=7 + k)[0] for k, env in enumerate(alone)]
        for actions in np.random.default_rng(0).uniform(-1, 1, size=(3, n, 1)).astype(np.float32):
            for key in ("eye", "mask"):
                scores = [agreement(tiles[key][k], frames[k][key]) for k in range(n)]
                assert min(scores) >= 0.98, (key, scores)
            tiles, rewards, terminated, truncated, info = batch.step(actions)
            _, plain_rewards, plain_terminated, plain_truncated, plain_info = plain.step(actions)
            assert np.array_equal(rewards, plain_rewards) and np.array_equal(
                terminated | truncated, plain_terminated | plain_truncated
            )
            assert all(np.array_equal(info["state"][name], plain_info["state"][name]) for name in plain_info["state"])
            frames = [env.step(actions[k])[0] for k, env in enumerate(alone)]
        assert mean_difference(tiles["eye"][0], tiles["eye"][1]) > 5  # each env its own camera, colours and background
    finally:
        for env in (batch, plain, *alone):
            env.close()


def test_a_batch_draws_dynamic_distractions_and_a_reset_envs_new_ones() -> None:
    """Goalie (its camera bound to the state): distractions drifting every step, and env 0, whose ball ends its episode
    first (step 21 of these actions), drawing its next episode's at its own autoreset; each tile as its env alone."""
    n, settings = 3, {"difficulty": 0.3, "dynamic": True}
    batch = visualenv.make_vec("Goalie-v0", n, batched=True, distractions=settings)
    alone = [visualenv.make("Goalie-v0", distractions=settings, noise="shared") for _ in range(n)]
    try:
        tiles, _ = batch.reset(seed=3)
        frames = [env.reset(seed=3 + k)[0] for k, env in enumerate(alone)]
        done, lone_resets = np.zeros(n, dtype=bool), 0
        for actions in np.random.default_rng(0).integers(0, 2, size=(24, n)):
            assert min(agreement(tiles[k], frames[k]) for k in range(n)) >= 0.98
            tiles, _, terminated, truncated, _ = batch.step(actions)
            frames = [env.reset()[0] if done[k] else env.step(int(actions[k]))[0] for k, env in enumerate(alone)]
            lone_resets += int(done.any() and not done.all())
            done = terminated | truncated
        assert lone_resets and min(agreement(tiles[k], frames[k]) for k in range(n)) >= 0.98
    finally:
        for env in (batch, *alone):
            env.close()


def test_what_a_batch_cannot_distract_is_refused_when_it_is_built(tmp_path: Path) -> None:
    """An orbiting camera turns each env's rays, which a depth observation cannot follow; without the camera's orbit the
    same batch is fine."""
    data = yaml.safe_load(segmented_cartpole(tmp_path).read_text(encoding="utf-8"))
    data["observation"]["cameras"]["mask"]["color"] = "depth"
    spec = tmp_path / "depth.yaml"
    spec.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    with pytest.raises(SpecError, match=r"camera 'fixed' turns with its distraction .* depth observation"):
        BatchedVectorEnv(spec, 2, distractions=0.2)
    BatchedVectorEnv(spec, 2, distractions={"difficulty": 0.2, "camera": False}).close()


@pytest.mark.parametrize(
    "given, message",
    [
        (
            {"difficulty": 0.1, "cam": True},
            "visualenv.make(): distractions.cam: unknown key 'cam' (did you mean 'camera'?",
        ),
        (
            {"difficulty": 3},
            "visualenv.make(): distractions.difficulty: expected a value less than or equal to 1, got 3",
        ),
        (
            "extreme",
            "visualenv.make(): distractions: expected a difficulty from 0 to 1, a level by name (easy, medium, hard) or a mapping",
        ),
    ],
)
def test_a_bad_option_says_what_was_expected(given, message) -> None:
    with pytest.raises(SpecError) as caught:
        visualenv.make("DMC-cartpole-swingup-v0", distractions=given)
    assert str(caught.value).startswith(message), str(caught.value)


@pytest.mark.parametrize("name, difficulty", [("easy", 0.1), ("medium", 0.2), ("hard", 0.3)])
def test_the_suites_levels_by_name(name, difficulty) -> None:
    env = visualenv.make("DMC-cartpole-swingup-v0", distractions=name)
    try:
        settings = env.unwrapped.distractions
        assert settings.difficulty == difficulty and settings.camera and settings.colors and settings.background
    finally:
        env.close()


def test_eval_plays_an_agent_on_distracted_episodes(tmp_path: Path) -> None:
    """`visualenv eval --distractions d`: the shipped agent on distracted observations, said so and not held to its results.json."""
    import json

    from click.testing import CliRunner

    from visualenv.cli import main

    out = tmp_path / "eval.json"
    result = CliRunner().invoke(
        main, ["eval", "Goalie-v0", "--model", "pretrained", "--episodes", "2", "--distractions", "0.2", "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert (
        "distracted at difficulty 0.2 (not compared with results.json)" in result.output
        and "reproduces" not in result.output
    )
    figures = json.loads(out.read_text())
    assert figures["distractions"] == 0.2 and figures["matches_results_json"] is None and figures["episodes"] == 2
    refused = CliRunner().invoke(main, ["eval", "Goalie-v0", "--model", "random", "--distractions", "0.2"])
    assert refused.exit_code == 2 and "--distractions" in refused.output
    unknown = CliRunner().invoke(main, ["eval", "Goalie-v0", "--model", "pretrained", "--distractions", "harder"])
    assert (
        unknown.exit_code == 2
        and "expected a difficulty from 0 to 1, easy, medium, hard, a range LOW:HIGH, or a distractions section"
        in unknown.output
    ), unknown.output


def test_eval_takes_a_distractions_section_as_a_mapping(tmp_path: Path) -> None:
    """`--distractions '{...}'`: any section a spec may hold (e.g. DAVIS videos as the background), checked as a spec's."""
    import json

    from click.testing import CliRunner

    from visualenv.cli import main

    out, section = tmp_path / "eval.json", "{difficulty: 0.2, camera: false, dynamic: true}"
    result = CliRunner().invoke(
        main,
        ["eval", "Goalie-v0", "--model", "pretrained", "--episodes", "1", "--distractions", section, "-o", str(out)],
    )
    assert result.exit_code == 0, result.output
    assert 'distracted by {"difficulty": 0.2, "camera": false, "dynamic": true}' in result.output, result.output
    assert json.loads(out.read_text())["distractions"] == {"difficulty": 0.2, "camera": False, "dynamic": True}
    for bad, message in [
        ("{difficulty: 0.2, colours: true}", "distractions.colours: unknown key 'colours' (did you mean 'colors'?"),
        ("{difficulty: 2}", "distractions.difficulty: expected a value less than or equal to 1, got 2"),
        ("{difficulty: [0.1}", "is not a YAML mapping"),
    ]:
        refused = CliRunner().invoke(main, ["eval", "Goalie-v0", "--model", "pretrained", "--distractions", bad])
        assert refused.exit_code == 2 and message in refused.output and "Traceback" not in refused.output, (
            refused.output
        )


TWO_NAMES = """id: TwoNames-v0
scene:
  objects:
    Pole:     {primitive: cube, size: 1, location: [-1, 0, 0], material: {color: [0.5, 0.5, 0.5]}}
    Pole-tip: {primitive: cube, size: 1, location: [1, 0, 0], material: {color: [0.5, 0.5, 0.5]}}
    Sun:      {light: sun, strength: 3.0}
    Camera:   {camera: perspective, location: [0, -6, 0], look_at: [0, 0, 0]}
state: {x: {init: 0.0}}
actions: {discrete: [{dx: 0.0}]}
dynamics: {update: {x: x + dx}}
observation: {camera: Camera, resolution: [32, 32], color: rgb}
distractions: {difficulty: 0.3, camera: false, background: false}
"""


def test_two_envs_in_one_process_draw_the_same_distractions(tmp_path: Path) -> None:
    """The second env's materials are Blender's "Pole.001" and "Pole-tip.001", which sort the other way round than
    "Pole" and "Pole-tip": the colours are shifted by name without that suffix, so a seed shifts each object alike."""
    spec = tmp_path / "two.yaml"
    spec.write_text(TWO_NAMES, encoding="utf-8")
    first, second = visualenv.make(spec), visualenv.make(spec)
    try:
        a, b = first.reset(seed=2)[0], second.reset(seed=2)[0]
        assert mean_difference(a, first_frames(spec, [2], distractions=0)[0]) > 5 and a.tobytes() == b.tobytes()
    finally:
        first.close()
        second.close()


def test_a_bound_colour_still_changes_under_shifted_colours(tmp_path: Path) -> None:
    """A colour binding and the distraction write one socket: the bound colour goes on changing every step, shifted."""
    spec = tmp_path / "bound.yaml"
    spec.write_text(
        TWO_NAMES.replace("state: {x: {init: 0.0}}", "state: {x: {init: 0.0}, red: {init: 0.1}}")
        .replace("dynamics: {update: {x: x + dx}}", "dynamics: {update: {x: x + dx, red: red + 0.3}}")
        .replace("distractions:", "actors: {Pole: {color: [red, 0.2, 0.2]}}\ndistractions:"),
        encoding="utf-8",
    )
    env = visualenv.make(spec)
    try:
        frames = [env.reset(seed=2)[0], *(env.step(0)[0] for _ in range(2))]
    finally:
        env.close()
    left = (slice(None), slice(0, 14))  # the Pole's half of the image: only its colour changes from step to step
    reds = [frame[left][..., 0].astype(int).sum() for frame in frames]
    assert reds[0] < reds[1] < reds[2], reds
