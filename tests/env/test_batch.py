"""Many envs in one Blender (BatchedVectorEnv): the same episodes as one env each, tiles equal to one env's render, clear refusals."""

from __future__ import annotations

import json
import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import visualenv
from visualenv.env.batch import BatchedVectorEnv
from visualenv.env.visual_env import VisualEnv
from visualenv.errors import SpecError
from visualenv.spec import load_spec_text
from visualenv.spec.loader import load_spec

pytestmark = pytest.mark.blender

SPECS = Path(__file__).parents[2] / "specs"
BUNDLED = sorted(SPECS.glob("*.yaml"))

#: a spec with a continuous action, a milestone, a conditional, a random draw at reset and a division that faults
FEATURES = """\
id: Features-v0
params: {k: 0.5}
state:
  x: {init: "uniform(-1, 1)"}
  v: {init: 0.0}
actions:
  continuous: {push: {low: -1, high: 1}, brake: {low: 0, high: 1}}
dynamics:
  let: {drag: "v * brake if abs(v) > 0.1 else 0.0"}
  update:
    x: x + v
    v: clip(v + push * k - drag, -2, 2)
reward: "-abs(x) + (1 if 0.2 < x < 0.5 else 0)"
outcomes:
  halfway: {when: abs(x) > 1.5, reward: 1, end: none, success: true}
  away: {when: abs(x) > 3, reward: -5}
max_steps: 40
"""


def step_both(batch: BatchedVectorEnv, singles: list[VisualEnv], steps: int) -> int:
    """Step a batch and one env per lane with the same actions (autoreset as Gymnasium's NEXT_STEP); returns the episodes ended."""
    ended = 0
    done = np.zeros(batch.num_envs, dtype=bool)
    for _ in range(steps):
        actions = np.array([batch.single_action_space.sample() for _ in range(batch.num_envs)])
        obs, rewards, terminated, truncated, info = batch.step(actions)
        for i, env in enumerate(singles):
            if done[i]:
                env.reset()
                assert rewards[i] == 0 and not terminated[i] and not truncated[i]
            else:
                action = actions[i] if batch.program.discrete is None else int(actions[i])
                _, reward, term, trunc, single_info = env.step(action)
                assert (reward, term, trunc) == (rewards[i], terminated[i], truncated[i])
                assert (
                    single_info["outcome"] == info["outcome"][i] and single_info["is_success"] == info["is_success"][i]
                )
                assert single_info["milestones"] == info["milestones"][i] and single_info["steps"] == info["steps"][i]
            assert env.state == {k: v[i] for k, v in info["state"].items() if not k.startswith("_")}
            done[i] = terminated[i] or truncated[i]
        ended += int(done.sum())
    return ended


@pytest.mark.parametrize("spec", [*BUNDLED, "features"], ids=lambda s: getattr(s, "stem", s))
def test_a_batch_runs_the_episodes_of_one_env_per_seed(spec):
    """Env i of a batch reset with seed s has the states, rewards and ends of visualenv.make reset with seed s + i."""
    loaded = load_spec_text(FEATURES, name="features.yaml") if spec == "features" else load_spec(spec)
    batch = BatchedVectorEnv(loaded, 4, render=False)
    singles = [VisualEnv(loaded, render=False) for _ in range(4)]
    obs, info = batch.reset(seed=11)
    for i, env in enumerate(singles):
        single_obs, _ = env.reset(seed=11 + i)
        assert np.array_equal(obs[i], single_obs)
    assert batch._batch.step is not None, "the bundled specs' steps are vectorised"
    assert step_both(batch, singles, 120) > 0


def test_a_step_that_draws_random_numbers_steps_each_env_alone_with_the_same_result():
    text = FEATURES.replace("x: x + v", "x: x + v + normal(0, 0.01)")
    loaded = load_spec_text(text, name="noisy.yaml")
    batch = BatchedVectorEnv(loaded, 3, render=False)
    assert batch._batch.step is None
    singles = [VisualEnv(loaded, render=False) for _ in range(3)]
    batch.reset(seed=5)
    for i, env in enumerate(singles):
        env.reset(seed=5 + i)
    step_both(batch, singles, 60)


def test_a_fault_in_one_env_is_the_located_fault_of_that_env():
    text = FEATURES.replace("x: x + v", "x: x + v / (x - x)").replace(
        "max_steps: 40", "max_steps: 40\non_fault: terminate"
    )
    batch = BatchedVectorEnv(load_spec_text(text, name="fault.yaml"), 2, render=False)
    batch.reset(seed=0)
    _, rewards, terminated, _, info = batch.step(np.zeros((2, 2), dtype=np.float32))
    assert terminated.all() and (rewards == 0).all()
    assert "dynamics.update.x" in info["error"][0] and "division by zero" in info["error"][0]


def test_autoreset_same_step_hands_back_the_final_observation():
    batch = BatchedVectorEnv(SPECS / "visual_cartpole.yaml", 2, render=False, autoreset_mode="same_step")
    batch.reset(seed=0)
    for _ in range(200):
        obs, _, terminated, truncated, info = batch.step(np.zeros(2, dtype=np.int64))
        if (terminated | truncated).any():
            i = int(np.flatnonzero(terminated | truncated)[0])
            assert info["_final_obs"][i] and info["final_info"]["outcome"][i] is not None
            assert info["steps"][i] == 0 and not np.array_equal(obs[i], info["final_obs"][i])
            return
    pytest.fail("no episode ended")


def test_gymnasium_make_vec_uses_the_vector_entry_point():
    vec = gym.make_vec("visualenv/VisualCartPole-v0", num_envs=3, vectorization_mode="vector_entry_point", render=False)
    assert isinstance(vec, BatchedVectorEnv) and vec.observation_space.shape == (3, 4)
    assert isinstance(visualenv.make_vec("VisualCartPole-v0", 2, batched=True, render=False), BatchedVectorEnv)


@pytest.mark.parametrize("n", [0, -1, 1.5, True])
def test_num_envs_below_one_or_not_an_integer_is_refused(n):
    with pytest.raises(ValueError, match="num_envs must be an integer of at least 1"):
        BatchedVectorEnv(SPECS / "visual_cartpole.yaml", n, render=False)


def test_bad_actions_and_per_env_wrappers_are_refused():
    batch = BatchedVectorEnv(SPECS / "visual_cartpole.yaml", 2, render=False)
    batch.reset(seed=0)
    with pytest.raises(ValueError, match="actions of shape"):
        batch.step(np.zeros(3, dtype=np.int64))
    with pytest.raises(ValueError, match="out of range"):
        batch.step(np.array([0, 2]))
    with pytest.raises(ValueError, match="takes no per-env wrappers"):
        visualenv.make_vec("VisualCartPole-v0", 2, batched=True, frame_stack=4)
    with pytest.raises(ValueError, match="autoreset_mode must be one of"):
        BatchedVectorEnv(SPECS / "visual_cartpole.yaml", 2, render=False, autoreset_mode="sometimes")


# -- rendering, with real Blender --------------------------------------------------------------------------


def agreement(a: np.ndarray, b: np.ndarray) -> float:
    """The share of pixels within 8 levels."""
    return float((np.abs(a.astype(int) - b.astype(int)) <= 8).mean())


def render_both(spec, n: int, steps: int, seed: int = 3) -> list[float]:
    """Per step and env: how far the batch's tile agrees with the env's own render (noise='shared', as a batch renders)."""
    loaded = spec if not isinstance(spec, Path) else load_spec(spec)
    batch = BatchedVectorEnv(loaded, n)
    singles = [VisualEnv(loaded, renderer_options={"noise": "shared"}) for _ in range(n)]
    try:
        obs, _ = batch.reset(seed=seed)
        own = [env.reset(seed=seed + i)[0] for i, env in enumerate(singles)]
        scores, moved = [], False
        first = obs.copy()
        for _ in range(steps):
            scores += [agreement(obs[i], own[i]) for i in range(n)]
            actions = np.array([batch.single_action_space.sample() for _ in range(n)])
            obs, _, terminated, truncated, _ = batch.step(actions)
            own = [
                env.step(actions[i] if batch.program.discrete is None else int(actions[i]))[0]
                for i, env in enumerate(singles)
            ]
            moved = moved or not np.array_equal(obs[0], first[0])
            if (terminated | truncated).any():
                break
        assert moved, "the scene should change over the steps (a test that cannot fail otherwise)"
        return scores
    finally:
        batch.close()
        for env in singles:
            env.close()


@pytest.mark.parametrize("spec", BUNDLED, ids=lambda s: s.stem)
def test_each_tile_is_the_envs_own_render(spec):
    """Tiles of one render call agree with one env per process on at least 98 % of pixels within 8 levels,
    for a fixed camera (VisualCartPole) and cameras bound to the state (Goalie, Hover2D)."""
    scores = render_both(spec, 3, 8)
    assert min(scores) >= 0.98, scores


def test_a_batch_past_the_image_limit_renders_in_several_calls(monkeypatch):
    from visualenv.render.blender.batch import calls as batch_calls, renderer as batched

    monkeypatch.setattr(batch_calls, "MAX_IMAGE_PIXELS", 2 * 100 * 100)  # two tiles a call: five envs take three calls
    calls: list[int] = []
    original = batched.BatchedBlenderRenderer.raw_render
    monkeypatch.setattr(batched.BatchedBlenderRenderer, "raw_render", lambda self: (calls.append(1), original(self))[1])
    scores = render_both(SPECS / "visual_cartpole.yaml", 5, 3)
    assert min(scores) >= 0.98, scores
    assert len(calls) >= 3 * 3  # three calls for each of the three observations


def test_a_batch_larger_than_one_image_renders_every_tile():
    """441 envs at 100x100 would be a 2,100 x 2,100 image, which Cycles' in-memory result returned black: two calls instead."""
    from visualenv.render.blender.batch.calls import MAX_IMAGE_PIXELS, envs_per_call
    from visualenv.render.blender.batch.tiles_camera import grid_shape

    per_call = envs_per_call(441, 100, 100)
    assert per_call < 441 and np.prod(grid_shape(per_call)) * 100 * 100 <= MAX_IMAGE_PIXELS
    batch = BatchedVectorEnv(SPECS / "visual_cartpole.yaml", 441)
    try:
        obs, _ = batch.reset(seed=0)
        assert obs.shape == (441, 100, 100, 1) and (obs.reshape(441, -1).max(axis=1) > 100).all()  # no black tile
    finally:
        batch.close()


def test_a_tile_shows_its_own_env_not_its_neighbours():
    """Two envs with different states: each tile follows its own env (swap the states and the tiles swap)."""
    batch = BatchedVectorEnv(SPECS / "visual_cartpole.yaml", 2)
    try:
        obs, _ = batch.reset(seed=0, options={"state": {"x": -1.5}})
        left = obs.copy()
        batch.lanes[1].reset(options={"state": {"x": 1.5}})
        batch._state[:, 1] = [batch.lanes[1].state[n] for n in batch.program.state_names]
        obs = batch._observe()
        assert agreement(obs[0], left[0]) == 1.0 and agreement(obs[1], left[1]) < 0.99
        centre = [np.nonzero(obs[i][..., 0] > 100)[1].mean() for i in range(2)]
        assert centre[1] > centre[0] + 20, centre
    finally:
        batch.close()


def test_a_blend_file_scene_batches(corpus):
    from tests.fixtures.blend_corpus import VARIANTS

    variant = VARIANTS["base"]
    text = f"""\
id: CorpusBatch-v0
scene: {{file: base.blend, world: {{color: [0, 0, 0], strength: 0}}}}
state: {{x: {{init: "uniform(-1.5, 1.5)"}}}}
actions: {{discrete: [{{u: -0.3}}, {{u: 0.3}}]}}
dynamics: {{update: {{x: x + u}}}}
actors:
  {json.dumps(variant.ball)}: {{location: [x, 0, 0]}}
observation: {{camera: {json.dumps(variant.camera)}, resolution: [48, 32], color: rgb}}
render: {{engine: cycles, preset: fast}}
"""
    scores = render_both(load_spec_text(text, name="corpus.yaml", base_dir=corpus), 3, 6)
    assert min(scores) >= 0.98, scores


def test_engines_and_cameras_a_batch_cannot_render_are_refused(tmp_path):
    base = (SPECS / "visual_cartpole.yaml").read_text()
    with pytest.raises(
        ValueError, match="render.engine 'workbench' cannot render a batch"
    ):  # refused when the batch is built
        BatchedVectorEnv(load_spec_text(base.replace("engine: cycles", "engine: workbench"), name="w.yaml"), 2)
    zooming = base.replace("actors:\n", "actors:\n  Camera: {lens: 30 + 10 * theta}\n", 1)
    with pytest.raises(
        SpecError, match=r"camera 'Camera' cannot be batched \(its lens binding on 'Camera'\): .* one lens"
    ):
        BatchedVectorEnv(load_spec_text(zooming, name="zooming.yaml"), 2)
    scaled = base.replace("actors:\n", "actors:\n  Camera: {scale: [1, 1, 1 + theta]}\n", 1)
    with pytest.raises(SpecError, match=r"cannot be batched \(its scale binding on 'Camera'\)"):
        BatchedVectorEnv(load_spec_text(scaled, name="scaled.yaml"), 2)
    turning = base.replace("actors:\n", "actors:\n  Camera: {rotation: [1.5, 0, theta]}\n", 1)
    BatchedVectorEnv(
        load_spec_text(turning, name="turning.yaml"), 2
    ).close()  # a turning camera is followed (test_batched_scale)


def test_several_cameras_give_a_dict_of_tiles_per_camera(tmp_path):
    """A Dict observation (grayscale 64x64 and RGB 40x40 here): one render call per camera, each key's tiles the env's own."""
    from tests.train.test_train_play import multi_camera_cartpole

    obs, owns = after_steps(load_spec(multi_camera_cartpole(tmp_path, "[40, 40]")), seed=1, actions=[0, 1, 1])
    assert {k: v.shape for k, v in obs.items()} == {"front": (3, 64, 64, 1), "side": (3, 40, 40, 3)}
    for i, own in enumerate(owns):
        assert all(agreement(obs[k][i], own[k]) >= 0.98 for k in own), i


def after_steps(loaded, *, seed: int, actions: list[int], steps: int = 3) -> tuple:
    """A batch's observations and each env's own render after `steps` steps of the same actions (env i seeded seed + i)."""
    batch = BatchedVectorEnv(loaded, len(actions))
    singles = [VisualEnv(loaded, renderer_options={"noise": "shared"}) for _ in actions]
    try:
        batch.reset(seed=seed)
        for _ in range(steps):
            obs, *_ = batch.step(np.array(actions))
        owns = []
        for i, env in enumerate(singles):
            env.reset(seed=seed + i)
            for _ in range(steps):
                own, *_ = env.step(actions[i])
            owns.append(own)
        return obs, owns
    finally:
        batch.close()
        for env in singles:
            env.close()


def test_sb3_adapter_hands_sb3_the_ended_episode_and_trains(tmp_path):
    """`train --batched N`: SB3's VecEnv over a batch reset in the same step, as SB3's own VecEnvs are."""
    from click.testing import CliRunner

    from visualenv.cli import main
    from visualenv.env.sb3_vec import make_sb3_batched

    vec = make_sb3_batched(str(SPECS / "visual_cartpole.yaml"), 2, seed=0, render=False)
    first = vec.reset()
    assert first.shape == (2, 4)
    for _ in range(300):
        obs, rewards, dones, infos = vec.step(np.array([0, 0]))
        if dones.any():
            i = int(np.flatnonzero(dones)[0])
            assert infos[i]["outcome"] == "fell" and "terminal_observation" in infos[i] and "episode" in infos[i]
            assert not np.array_equal(infos[i]["terminal_observation"], obs[i])  # obs is the next episode's first
            break
    else:
        pytest.fail("no episode ended")
    vec.close()
    out = tmp_path / "runs"
    result = CliRunner().invoke(
        main,
        [
            "train",
            "VisualCartPole-v0",
            "--batched",
            "2",
            "--state-only",
            "--steps",
            "64",
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
            "--device",
            "cpu",
            "--out",
            str(out),
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    (run,) = (out / "VisualCartPole-v0").iterdir()
    config = json.loads((run / "config.json").read_text())["config"]
    assert config["batched"] is True and config["hyperparams"]["device"] == "cpu"
    log = run / "monitor" / "batch.monitor.csv"
    before = log.read_text().splitlines()
    assert len(before) > 2  # the header lines and at least one episode
    assert '"env_id": "visualenv/VisualCartPole-v0"' in before[0]
    assert re.search(r"^eval at \d+ steps: mean return .* over 1 episodes, success [01]/1$", result.output, re.M), (
        result.output
    )
    resumed = CliRunner().invoke(
        main, ["train", "VisualCartPole-v0", "--resume", str(run), "--steps", "128", "--no-progress"]
    )
    assert resumed.exit_code == 0, resumed.output
    after = log.read_text().splitlines()
    assert after[: len(before)] == before and len(after) > len(before)  # the resumed run appends its episodes


def test_a_child_object_moves_with_its_own_copys_parent():
    """The pole parented to the cart: each copy's pole hangs from that copy's cart (parents are remapped per copy)."""
    text = (SPECS / "visual_cartpole.yaml").read_text()
    text = text.replace(
        "  Pole: {location: [x, 0, 0.125], rotation: [0, theta, 0]}", "  Pole: {rotation: [0, theta, 0]}"
    )
    text = text.replace(
        "depth: 1.0, origin: bottom,", "depth: 1.0, origin: bottom, parent: Cart, location: [0, 0, 0.125],"
    )
    assert "parent: Cart" in text and "Pole: {rotation" in text
    scores = render_both(load_spec_text(text, name="parented.yaml", base_dir=SPECS), 3, 8)
    assert min(scores) >= 0.98, scores


@pytest.mark.parametrize(
    "spec, depth_range",
    [("visual_cartpole.yaml", "[4, 9]"), ("goalie.yaml", "[1, 30]")],
    ids=["fixed_camera", "moving_camera"],
)
def test_depth_tiles_are_the_envs_own_depth(spec, depth_range):
    """Depth in a batch is measured along each tile's own ray: the third env sits a grid row away from the shared
    camera pose, where the scene camera's view Z would be off by the copies' spacing (all background)."""
    text = (SPECS / spec).read_text().replace("color: grayscale", f"color: depth\n  depth_range: {depth_range}")
    obs, owns = after_steps(load_spec_text(text, name=spec), seed=3, actions=[0, 1, 1])
    for i, own in enumerate(owns):
        near = own[..., 0] < 255  # what the env sees nearer than the far end of the range
        assert near.mean() > 0.01 and np.ptp(own) > 60, "a depth image, not the background alone"
        assert agreement(obs[i][near], own[near]) >= 0.98 and agreement(obs[i], own) >= 0.98, i


def test_render_gives_each_envs_own_view():
    """render_mode='rgb_array': a tuple of N high-resolution views, each the view of the env alone (from gymnasium.make_vec too)."""
    text = (
        (SPECS / "goalie.yaml")
        .read_text()
        .replace(
            "render: {engine: cycles, preset: fast}",
            "render: {engine: cycles, preset: fast, view: {resolution: [120, 90], preset: fast}}",
        )
    )
    loaded = load_spec_text(text, name="goalie.yaml")
    batch = BatchedVectorEnv(loaded, 3, render_mode="rgb_array")
    single = VisualEnv(loaded, render_mode="rgb_array", renderer_options={"noise": "shared"})
    try:
        batch.reset(seed=5)
        for _ in range(4):
            obs, *_ = batch.step(np.array([0, 1, 1]))
        views = batch.render()
        assert (
            isinstance(views, tuple)
            and len(views) == 3
            and all(v.shape == (90, 120, 3) and v.dtype == np.uint8 for v in views)
        )
        for i in range(3):
            single.reset(seed=5 + i)
            for _ in range(4):
                single.step(int([0, 1, 1][i]))
            assert agreement(views[i], single.render()) >= 0.98, i
        assert agreement(views[0], views[1]) < 0.98  # the goalies stand in different places
        after, *_ = batch.step(
            np.array([1, 1, 1])
        )  # observations after a view are still the env's own (the single env is env 2)
        own, *_ = single.step(1)
        assert agreement(after[2], own) >= 0.98
    finally:
        batch.close()
        single.close()
    with pytest.raises(ValueError, match="render_mode must be one of"):
        BatchedVectorEnv(loaded, 2, render_mode="ansi")  # "human" shows a grid: tests/viewer/test_human.py
    vec = gym.make_vec("visualenv/Goalie-v0", 2, vectorization_mode="vector_entry_point", render_mode="rgb_array")
    assert (
        vec.render_mode == "rgb_array" and "rgb_array" in vec.metadata["render_modes"]
    )  # (its 400x400 'quality' views take seconds)
    vec.close()


@pytest.mark.parametrize("alone", [True, False], ids=["alone", "all_again"])
def test_same_step_autoreset_renders_only_the_reset_envs_again(monkeypatch, alone):
    """SAME_STEP: an ended env's final frame and its next episode's first frame are the frames a NEXT_STEP batch
    shows one step apart. The reset envs are rendered alone (one env-sized call each) where that costs less than
    every tile again (alone_limit, set here so that both ways are seen with 3 envs), else the grid is rendered again."""
    from visualenv.render.blender.batch import renderer as batched

    monkeypatch.setattr(
        batched, "alone_limit", (lambda n, device, threads: n) if alone else (lambda n, device, threads: 0)
    )
    same = BatchedVectorEnv(SPECS / "visual_cartpole.yaml", 3, autoreset_mode="same_step")
    nxt = BatchedVectorEnv(SPECS / "visual_cartpole.yaml", 3)
    pixels: list[int] = []
    render = same.renderer._render
    same.renderer._render = lambda view: (pixels.append(view.width * view.height), render(view))[
        1
    ]  # counts, Blender renders
    try:
        same.reset(seed=4)
        nxt.reset(seed=4)
        actions = np.array([0, 0, 1])  # the two envs pushed left fall first
        for _ in range(60):
            pixels.clear()
            obs, _, terminated, truncated, info = same.step(actions)
            expected, *_ = nxt.step(actions)
            done = terminated | truncated
            if done.any():
                break
            assert all(agreement(obs[i], expected[i]) == 1.0 for i in range(3))
        else:
            pytest.fail("no episode ended")
        assert 0 < done.sum() < 3
        ended = np.flatnonzero(done)
        for i in ended:
            assert agreement(info["final_obs"][i], expected[i]) >= 0.98
        for i in np.flatnonzero(~done):
            assert agreement(obs[i], expected[i]) >= 0.98
        again = [100 * 100] * len(ended) if alone else [4 * 100 * 100]  # each reset tile alone, or the grid again
        assert pixels == [4 * 100 * 100] + again, pixels  # after the 2 x 2 grid of the step
        first, *_ = nxt.step(actions)  # NEXT_STEP resets the ended envs now, with the same draws
        for i in ended:
            assert (
                agreement(obs[i], first[i]) >= 0.98 and agreement(obs[i], info["final_obs"][i]) < 0.998
            )  # the pole stands again
    finally:
        same.close()
        nxt.close()


def test_reset_envs_are_rendered_alone_only_while_that_is_cheaper():
    """One env alone is a call over the whole scene (its cost grows with N); the grid again costs N tiles, cheap on
    many threads and on a GPU. So the limit grows slower than N, is lower on a GPU and with more threads, and few
    envs never render alone past the camera switch's cost."""
    from visualenv.render.blender.batch.calls import ALONE_OVERHEAD_TILES, alone_limit

    cpu2, cpu16, gpu = (alone_limit(1024, "CPU", 2), alone_limit(1024, "CPU", 16), alone_limit(1024, "GPU", 16))
    assert gpu < cpu16 < cpu2 < 1024 - ALONE_OVERHEAD_TILES
    assert alone_limit(4096, "CPU", 2) / alone_limit(1024, "CPU", 2) == pytest.approx(2.0)  # 4x the envs, 2x the limit
    assert alone_limit(16, "CPU", 2) <= 0 and alone_limit(20, "CPU", 1) == 20 - ALONE_OVERHEAD_TILES


def test_reset_envs_rendered_alone_follow_a_moving_camera(monkeypatch):
    """Goalie's camera moves with the state: an env rendered alone after SAME_STEP's reset is still its own view."""
    from visualenv.render.blender.batch import renderer as batched

    monkeypatch.setattr(batched, "alone_limit", lambda n, device, threads: n)
    same = BatchedVectorEnv(SPECS / "goalie.yaml", 3, autoreset_mode="same_step")
    nxt = BatchedVectorEnv(SPECS / "goalie.yaml", 3)
    try:
        same.reset(seed=4)
        nxt.reset(seed=4)
        actions = np.array([0, 1, 0])
        for _ in range(60):
            obs, _, terminated, truncated, info = same.step(actions)
            expected, *_ = nxt.step(actions)
            if (terminated | truncated).any():
                break
        else:
            pytest.fail("no episode ended")
        first, *_ = nxt.step(actions)
        for i in np.flatnonzero(terminated | truncated):
            assert agreement(info["final_obs"][i], expected[i]) >= 0.98
            assert agreement(obs[i], first[i]) >= 0.98 and agreement(obs[i], info["final_obs"][i]) < 0.95
    finally:
        same.close()
        nxt.close()
