"""DeepMind Control, reproduced: DMC-cartpole-swingup-v0 steps as dm_control.suite's cartpole swingup does.

Against the installed dm_control (the ``dmc`` extra, which ``make setup`` installs): with the same
seed (``reset(seed=s)`` and ``task_kwargs={"random": s}``) and the same float64 actions, the
state-only env with ``action_repeat=1`` has dm_control's physics state after the first reset, and
qpos, qvel, the observation and the reward agree to 1e-9 over the 1,000 steps of an episode,
which both end there; the second episode's reset (the random stream continued) and steps too.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import pickle
import re
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault(
    "MUJOCO_GL", "disable"
)  # dm_control looks for an OpenGL display on import; these tests render nothing there
mujoco = pytest.importorskip("mujoco")
suite = pytest.importorskip("dm_control.suite")

import visualenv  # noqa: E402
from visualenv.env.batch import BatchedVectorEnv  # noqa: E402
from visualenv.physics.simulation import integration_state  # noqa: E402

ID = "DMC-cartpole-swingup-v0"
ASSETS = Path(__file__).resolve().parents[2] / "specs" / "dmc" / "assets"


def test_the_pinned_files_are_dm_controls_own() -> None:
    """The copies are dm_control's files (SOURCES.md's sha256 of each original), byte for byte where SOURCES.md says
    verbatim, and each task's copy compiles to the model dm_control's loader builds (with reacher's one camera renamed)."""
    text = (ASSETS / "SOURCES.md").read_text(encoding="utf-8")
    version = re.search(r"^dm_control (\S+) ", text, re.M)
    assert version is not None and "Apache License" in (ASSETS / "LICENSE.dm_control").read_text(encoding="utf-8")
    rows = {  # a copy, the sha256 of dm_control's file (the one it was built from, where it names one), how it is here
        name: (sha, original or name, how)
        for name, sha, original, how in re.findall(
            r"^\| `([\w./]+)` \| `([0-9a-f]{64})`(?: \(`([\w./]+)`\))? \| ([^|]+) \|", text, re.M
        )
    }
    assert sorted(rows) == sorted(p.relative_to(ASSETS).as_posix() for p in ASSETS.rglob("*.xml"))
    verbatim = [name for name, (_, _, how) in rows.items() if how.strip() == "verbatim"]
    for name in verbatim:
        assert hashlib.sha256((ASSETS / name).read_bytes()).hexdigest() == rows[name][0], name
    assert sorted(set(rows) - set(verbatim)) == [
        "cheetah.xml",
        "quadruped_run.xml",
        "quadruped_walk.xml",
        "reacher.xml",
    ]
    if metadata.version("dm_control") != version.group(1):
        pytest.skip(f"dm_control {metadata.version('dm_control')} is installed; the copies are of {version.group(1)}")
    found = importlib.util.spec_from_file_location("vendor_dm_control", ASSETS / "vendor_dm_control.py")
    assert found is not None and found.loader is not None
    vendor = importlib.util.module_from_spec(found)
    found.loader.exec_module(vendor)
    theirs = Path(suite.__file__).parent
    for name, (sha, original, _) in rows.items():
        assert hashlib.sha256((theirs / original).read_bytes()).hexdigest() == sha, name
    for name in verbatim:
        assert (theirs / name).read_bytes() == (ASSETS / name).read_bytes(), name
    assert sorted([*vendor.MODELS, *vendor.BUILT]) == sorted(p.name for p in ASSETS.glob("*.xml"))
    for name, module in vendor.MODELS.items():
        vendor.check(name, module)  # SystemExit if the copy compiles to another model
    for name in vendor.BUILT:
        vendor.check_built(name)  # the same, against the model suite.load steps
    cheetah = (ASSETS / "cheetah.xml").read_text(encoding="utf-8")
    assert "settotalmass" not in re.search(r"<compiler [^>]*>", cheetah).group(0) and cheetah.count("<inertial ") == 7
    mass = re.search(r'<body name="torso"[^>]*>\n *<inertial [^>]* mass="([^"]+)"', cheetah).group(1)
    heavier = cheetah.replace(f'mass="{mass}"', f'mass="{np.nextafter(float(mass), np.inf)!r}"', 1)
    assets = importlib.import_module("dm_control.suite.cheetah").get_model_and_assets()[1]
    expected = vendor.binary(vendor.expected_model("cheetah.xml", "dm_control.suite.cheetah"))
    assert (
        vendor.binary(vendor.compile_quietly(heavier, assets)) != expected
    )  # the control: the comparison sees one bit


def their_observation(time_step) -> np.ndarray:
    return np.concatenate([time_step.observation["position"], time_step.observation["velocity"]])


def assert_same_state(ours, theirs, where: str) -> None:
    data, physics = ours.unwrapped.data, theirs.physics
    np.testing.assert_array_equal(data.qpos, physics.data.qpos, err_msg=where)
    np.testing.assert_array_equal(data.qvel, physics.data.qvel, err_msg=where)
    np.testing.assert_array_equal(
        integration_state(data), integration_state(physics.data.ptr), err_msg=where
    )  # warm start and time too


@pytest.mark.parametrize("seed", [0, 7, 123])
def test_cartpole_swingup_equals_dm_control_over_two_episodes(seed: int) -> None:
    ours = visualenv.make(ID, render=False, action_repeat=1)
    theirs = suite.load("cartpole", "swingup", task_kwargs={"random": seed})
    actions = np.random.default_rng(1000 + seed)
    obs, _ = ours.reset(seed=seed)
    time_step = theirs.reset()
    for episode in range(2):
        where = f"seed {seed} episode {episode}"
        assert_same_state(ours, theirs, where + " reset")
        np.testing.assert_allclose(obs, their_observation(time_step), rtol=0, atol=1e-9, err_msg=where)
        for step in range(1000):
            action = actions.uniform(-1.0, 1.0, size=1)
            obs, reward, terminated, truncated, _ = ours.step(action)
            time_step = theirs.step(action)
            here = f"{where} step {step}"
            np.testing.assert_allclose(
                ours.unwrapped.data.qpos, theirs.physics.data.qpos, rtol=0, atol=1e-9, err_msg=here
            )
            np.testing.assert_allclose(
                ours.unwrapped.data.qvel, theirs.physics.data.qvel, rtol=0, atol=1e-9, err_msg=here
            )
            np.testing.assert_allclose(obs, their_observation(time_step), rtol=0, atol=1e-9, err_msg=here)
            assert abs(reward - time_step.reward) <= 1e-9, (here, reward, time_step.reward)
            assert not terminated
            assert truncated == time_step.last() == (step == 999), here  # dm_control's time limit: 10 s of 0.01 s steps
        obs, _ = ours.reset()  # no seed: both streams go on
        time_step = theirs.reset()


def test_first_resets_equal_dm_controls_on_many_seeds() -> None:
    ours = visualenv.make(ID, render=False, action_repeat=1)
    for seed in range(15):
        ours.reset(seed=seed)
        theirs = suite.load("cartpole", "swingup", task_kwargs={"random": seed})
        theirs.reset()
        assert_same_state(ours, theirs, f"seed {seed}")


def test_the_env_is_dm_controls_task_as_gymnasium_sees_it() -> None:
    env = visualenv.make(ID, render=False)
    theirs = suite.load("cartpole", "swingup")
    spec = theirs.action_spec()
    assert isinstance(env.unwrapped.data, mujoco.MjData) and isinstance(env.unwrapped.model, mujoco.MjModel)
    assert (
        env.action_space.shape == spec.shape
        and (env.action_space.low == spec.minimum).all()
        and (env.action_space.high == spec.maximum).all()
    )
    assert env.observation_space.shape == (5,) and env.observation_space.dtype == np.float64
    assert env.unwrapped.model.opt.timestep == theirs.physics.timestep() == 0.01
    assert env.unwrapped.action_repeat == 8 and env.unwrapped.max_episode_steps == 125  # PlaNet's repeat for cartpole


@pytest.mark.parametrize("repeat, steps", [(8, 125), (3, 334)])
def test_action_repeat_sums_dm_controls_rewards_and_keeps_its_time_limit(repeat: int, steps: int) -> None:
    """k control steps per step(): the rewards of dm_control's k steps summed; 1,000 control steps an episode, the last step shorter."""
    ours = visualenv.make(ID, render=False, action_repeat=repeat)
    theirs = suite.load("cartpole", "swingup", task_kwargs={"random": 5})
    ours.reset(seed=5)
    theirs.reset()
    actions = np.random.default_rng(5)
    for step in range(steps):
        action = actions.uniform(-1.0, 1.0, size=1)
        _, reward, terminated, truncated, info = ours.step(action)
        total = 0.0
        for _ in range(repeat):
            time_step = theirs.step(action)
            total += time_step.reward
            if time_step.last():
                break
        assert abs(reward - total) <= 1e-9, (step, reward, total)
        np.testing.assert_allclose(ours.unwrapped.data.qpos, theirs.physics.data.qpos, rtol=0, atol=1e-9)
        assert truncated == time_step.last() == (step == steps - 1) and not terminated
    assert info["steps"] == 1000


def test_gymnasium_make_and_its_time_limit() -> None:
    """The registered id has no TimeLimit of its own (a repeat given to make would make it wrong): the env truncates itself."""
    import gymnasium as gym

    assert gym.spec(f"visualenv/{ID}").max_episode_steps is None
    for repeat, steps in ((None, 125), (4, 250)):
        env = gym.make(f"visualenv/{ID}", render=False, **({} if repeat is None else {"action_repeat": repeat}))
        env.reset(seed=0)
        count, truncated = 0, False
        while not truncated:
            _, _, _, truncated, _ = env.step(env.action_space.sample())
            count += 1
        assert count == steps
        env.close()


def test_a_pickled_env_continues_dm_controls_stream() -> None:
    env = visualenv.make(ID, render=False, action_repeat=1)
    env.reset(seed=3)
    for _ in range(10):
        env.step(np.array([0.5]))
    copy = pickle.loads(pickle.dumps(env))
    for a in (env, copy):
        a.step(np.array([-0.25]))
    np.testing.assert_array_equal(env.unwrapped.data.qpos, copy.unwrapped.data.qpos)
    env.reset()
    copy.reset()  # the second episode's draws: the same stream, carried over
    np.testing.assert_array_equal(env.unwrapped.data.qpos, copy.unwrapped.data.qpos)
    np.testing.assert_array_equal(env.unwrapped.data.qvel, copy.unwrapped.data.qvel)


def test_a_seed_beyond_dm_controls_range_still_gives_one_stream() -> None:
    """RandomState takes seeds below 2**32; a larger one (evaluation seeds can be) seeds it from its 32-bit words."""
    a, b = (visualenv.make(ID, render=False) for _ in range(2))
    a.reset(seed=2**40 + 5)
    b.reset(seed=2**40 + 5)
    np.testing.assert_array_equal(a.unwrapped.data.qpos, b.unwrapped.data.qpos)
    b.reset(seed=5)
    assert not np.array_equal(a.unwrapped.data.qpos, b.unwrapped.data.qpos)


def test_a_batch_repeats_actions_as_dm_controls_benchmarks_do() -> None:
    """At the task's action repeat (8), a batch's step is 8 of dm_control's steps with the same action, rewards summed."""
    batch = BatchedVectorEnv(ID, 2, render=False)
    assert batch.action_repeat == 8 and batch.max_episode_steps == 125
    batch.reset(seed=5)
    theirs = [suite.load("cartpole", "swingup", task_kwargs={"random": 5 + i}) for i in range(2)]
    for t in theirs:
        t.reset()
    actions = np.random.default_rng(1)
    for _ in range(30):
        action = actions.uniform(-1, 1, size=(2, 1))
        _, rewards, *_ = batch.step(action)
        for i, t in enumerate(theirs):
            summed = sum(t.step(action[i]).reward for _ in range(8))
            assert abs(rewards[i] - summed) <= 1e-8
    batch.close()


def test_a_batch_steps_as_dm_control_with_action_repeat_1() -> None:
    batch = BatchedVectorEnv(ID, 2, render=False, action_repeat=1)
    batch.reset(seed=11)
    theirs = [suite.load("cartpole", "swingup", task_kwargs={"random": 11 + i}) for i in range(2)]
    for t in theirs:
        t.reset()
    actions = np.random.default_rng(0)
    for _ in range(200):
        action = actions.uniform(-1, 1, size=(2, 1))
        _, rewards, *_ = batch.step(action)
        for i, t in enumerate(theirs):
            time_step = t.step(action[i])
            assert abs(rewards[i] - time_step.reward) <= 1e-9
            np.testing.assert_allclose(batch.lanes[i].data.qpos, t.physics.data.qpos, rtol=0, atol=1e-9)
    batch.close()
