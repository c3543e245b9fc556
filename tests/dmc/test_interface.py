"""visualenv.dmc.load: a dm_env.Environment that steps as dm_control's suite.load + pixels.Wrapper do.

States, rewards, discounts and step types are compared step for step with dm_control's own env on the same seeds
(through its pixels.Wrapper where this machine has an OpenGL platform for MuJoCo, else the suite's env under it,
which is what the wrapper steps); DrQ-v2's wrappers' contract (action scaling, action repeat, a channels-first frame
stack over dm_env TimeSteps) runs over it.
"""

from __future__ import annotations

import collections
import os
from typing import Any

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "disable")  # dm_control looks for an OpenGL display on import
pytest.importorskip("mujoco")
suite = pytest.importorskip("dm_control.suite")
dm_env = pytest.importorskip("dm_env")

from dm_control.suite.wrappers import action_scale, pixels  # noqa: E402
from dm_env import StepType, specs  # noqa: E402

from visualenv import dmc  # noqa: E402


def theirs(seed: int, *, flat: bool = False) -> Any:
    env = suite.load(
        "cartpole",
        "swingup",
        task_kwargs={"random": seed},
        environment_kwargs={"flat_observation": True} if flat else None,
    )
    if flat:
        return env
    try:
        return pixels.Wrapper(env, pixels_only=True, render_kwargs=dict(height=84, width=84, camera_id=0))
    except Exception:  # no OpenGL platform for MuJoCo here: its pixels wrapper would step this env
        return env


def assert_same_step(mine: Any, other: Any, where: str) -> None:
    assert mine.step_type == other.step_type, where
    assert mine.discount == other.discount, where
    if other.reward is None:
        assert mine.reward is None, where
    else:
        assert abs(mine.reward - other.reward) <= 1e-9, (where, mine.reward, other.reward)


@pytest.mark.parametrize("seed", [0, 5])
def test_the_state_interface_steps_as_dm_control_over_two_episodes(seed: int) -> None:
    """render=False: dm_control's flat observation under "observations", the time limit a LAST with discount 1, the
    next step after it a FIRST whose reset continues the task's stream."""
    mine, other = dmc.load("cartpole", "swingup", task_kwargs={"random": seed}, render=False), theirs(seed, flat=True)
    assert mine.observation_spec() == other.observation_spec()
    assert mine.action_spec() == other.action_spec()
    actions = np.random.default_rng(seed)
    a, b = mine.reset(), other.reset()
    for step in range(2002):
        where = f"seed {seed} step {step}"
        assert_same_step(a, b, where)
        np.testing.assert_allclose(a.observation["observations"], b.observation["observations"], atol=1e-9, rtol=0)
        np.testing.assert_array_equal(mine.physics.named.data.qpos, other.physics.named.data.qpos, err_msg=where)
        action = actions.uniform(-1, 1, size=1)
        a, b = mine.step(action), other.step(action)  # after LAST both begin the next episode
    assert [mine.step(np.zeros(1)).step_type for _ in range(2)] == [StepType.MID] * 2


@pytest.mark.parametrize("domain, task", [("reacher", "hard"), ("finger", "turn_easy"), ("finger", "turn_hard")])
def test_the_tasks_whose_reset_writes_sizes_and_sites_step_as_dm_control(domain: str, task: str) -> None:
    """reacher hard (the target's size) and finger turn (the target site's place and radius, from the hinge's anchor):
    dm_control's flat observation spec, and its observations, rewards and qpos over a few steps."""
    mine = dmc.load(domain, task, task_kwargs={"random": 3}, render=False)
    other = suite.load(domain, task, task_kwargs={"random": 3}, environment_kwargs={"flat_observation": True})
    assert mine.observation_spec() == other.observation_spec() and mine.action_spec() == other.action_spec()
    actions = np.random.default_rng(3)
    a, b = mine.reset(), other.reset()
    for step in range(30):
        assert_same_step(a, b, f"step {step}")
        np.testing.assert_allclose(a.observation["observations"], b.observation["observations"], atol=1e-9, rtol=0)
        np.testing.assert_array_equal(mine.physics.named.data.qpos, other.physics.named.data.qpos)
        action = actions.uniform(-1, 1, size=other.action_spec().shape)
        a, b = mine.step(action), other.step(action)


@pytest.mark.blender
def test_the_pixels_interface_is_dm_controls_layout_and_steps_as_it_does() -> None:
    mine, other = dmc.load("cartpole", "swingup", task_kwargs={"random": 2}), theirs(2)
    assert mine.observation_spec() == collections.OrderedDict(pixels=specs.Array((84, 84, 3), np.uint8, "pixels"))
    assert mine.action_spec() == other.action_spec()
    a, b = mine.reset(), other.reset()
    first = a.observation["pixels"]
    for step in range(25):
        assert_same_step(a, b, f"step {step}")
        assert a.observation["pixels"].dtype == np.uint8 and a.observation["pixels"].shape == (84, 84, 3)
        np.testing.assert_array_equal(mine.physics.data.qpos, other.physics.data.qpos)
        a, b = mine.step(np.ones(1)), other.step(np.ones(1))
    moved = np.abs(a.observation["pixels"].astype(int) - first).max(axis=2) > 30
    assert moved.sum() > 20, "pushed right for 25 steps, the cart is drawn elsewhere"


class ActionRepeat(dm_env.Environment):
    """DrQ-v2's action repeat over dm_env: rewards summed, discounts multiplied, stopped at LAST."""

    def __init__(self, env: Any, repeats: int) -> None:
        self._env, self._repeats = env, repeats

    def step(self, action: Any) -> Any:
        reward, discount = 0.0, 1.0
        for _ in range(self._repeats):
            time_step = self._env.step(action)
            reward += (time_step.reward or 0.0) * discount
            discount *= time_step.discount
            if time_step.last():
                break
        return time_step._replace(reward=reward, discount=discount)

    def reset(self) -> Any:
        return self._env.reset()

    def observation_spec(self) -> Any:
        return self._env.observation_spec()

    def action_spec(self) -> Any:
        return self._env.action_spec()


class ChannelsFirstStack(dm_env.Environment):
    """DrQ-v2's frame stack: the last k frames channels first, the first frame repeated at reset."""

    def __init__(self, env: Any, k: int) -> None:
        self._env, self._frames = env, collections.deque(maxlen=k)
        shape = env.observation_spec()["pixels"].shape
        self._spec = specs.BoundedArray((shape[2] * k, *shape[:2]), np.uint8, 0, 255, "observation")

    def _stacked(self, time_step: Any) -> Any:
        return time_step._replace(observation=np.concatenate(list(self._frames), axis=0))

    def reset(self) -> Any:
        time_step = self._env.reset()
        for _ in range(self._frames.maxlen):
            self._frames.append(time_step.observation["pixels"].transpose(2, 0, 1).copy())
        return self._stacked(time_step)

    def step(self, action: Any) -> Any:
        time_step = self._env.step(action)
        self._frames.append(time_step.observation["pixels"].transpose(2, 0, 1).copy())
        return self._stacked(time_step)

    def observation_spec(self) -> Any:
        return self._spec

    def action_spec(self) -> Any:
        return self._env.action_spec()


@pytest.mark.blender
def test_drq_v2s_wrappers_run_over_it_and_its_own_stack_repeats_the_first_frame() -> None:
    env = dmc.load("cartpole", "swingup", task_kwargs={"random": 1})
    env = ChannelsFirstStack(ActionRepeat(action_scale.Wrapper(env, minimum=-1.0, maximum=1.0), 2), 3)
    time_step = env.reset()
    assert time_step.observation.shape == (9, 84, 84) and env.observation_spec().shape == (9, 84, 84)
    for _ in range(5):
        time_step = env.step(np.full(1, 0.5, np.float32))
        assert time_step.mid() and time_step.discount == 1.0 and 0.0 <= time_step.reward <= 2.0
    assert not np.array_equal(time_step.observation[:3], time_step.observation[6:]), "the cart moved between frames"
    stacked = dmc.load("cartpole", "swingup", task_kwargs={"random": 1}, frame_stack=3).reset().observation["pixels"]
    assert stacked.shape == (84, 84, 9) and np.array_equal(stacked[..., :3], stacked[..., 6:])
    zeros = dmc.load("cartpole", "swingup", frame_stack=3, padding="zeros").reset().observation["pixels"]
    assert not zeros[..., :6].any() and zeros[..., 6:].any()


def test_what_the_spec_fixes_is_refused_with_what_it_renders() -> None:
    with pytest.raises(ValueError, match="84x84 from camera 'fixed' \\(camera_id 0\\), not 64x64"):
        dmc.load("cartpole", "swingup", render_kwargs=dict(height=64, width=64, camera_id=0))
    with pytest.raises(ValueError, match="only 'random' is"):
        dmc.load("cartpole", "swingup", task_kwargs={"time_limit": 5})
    with pytest.raises(ValueError, match="render=False"):
        dmc.load("cartpole", "swingup", render=False, render_kwargs=dict(height=84))


@pytest.mark.parametrize("task", ["walk", "run"])
def test_quadrupeds_action_spec_is_dm_controls_and_it_steps_as_dm_control(task: str) -> None:
    """Quadruped's actions range from -1, -0.8 to 0.8, 1, 1.1 in float64 as dm_control's (the Box holds them as float32),
    and it steps as dm_control's with DrQ-v2's camera 2 accepted."""
    mine = dmc.load("quadruped", task, task_kwargs={"random": 5}, render=False)
    other = suite.load("quadruped", task, task_kwargs={"random": 5}, environment_kwargs={"flat_observation": True})
    assert mine.observation_spec() == other.observation_spec() and mine.action_spec() == other.action_spec()
    actions = np.random.default_rng(5)
    a, b = mine.reset(), other.reset()
    for step in range(20):
        assert_same_step(a, b, f"step {step}")
        np.testing.assert_allclose(a.observation["observations"], b.observation["observations"], atol=1e-9, rtol=0)
        action = actions.uniform(-1, 1, size=other.action_spec().shape)
        a, b = mine.step(action), other.step(action)
    with pytest.raises(ValueError, match="from camera 'y' \\(camera_id 2\\), not 84x84 from 'global'"):
        dmc.load("quadruped", task, render_kwargs=dict(height=84, width=84, camera_id=0))
