"""A pickled env goes on with its episode (issue 40): the copy's next steps are the original's, bit for bit.

State, step count, milestones, the random generators (the env's, the action space's, the sensor noise's) and a
physics spec's MuJoCo state are carried; the renderer is rebuilt and posed from the state.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
from gymnasium.error import ResetNeeded

import visualenv
from visualenv.env import VisualEnv
from visualenv.spec.loader import load_spec_text

ROOT = Path(__file__).resolve().parents[2]

#: random draws in every step, a milestone, and episodes ended by an outcome and by max_steps
NOISY = """\
id: NoisyWalk-v0
state:
  x: {init: "uniform(-0.5, 0.5)"}
  v: {init: 0}
actions:
  continuous:
    push: {low: -1, high: 1}
dynamics:
  update:
    v: v + 0.1 * push + normal(0, 0.05)
    x: x + v
reward: -abs(x)
outcomes:
  moved: {when: abs(x) > 0.3, end: none, success: true}
  gone: {when: abs(x) > 3}
max_steps: 12
"""


def _run(env, actions) -> list:
    """(obs, reward, terminated, truncated, info) of each action, resetting (without a seed) when an episode ends."""
    out = []
    for action in actions:
        step = env.step(action)
        out.append(step)
        if step[2] or step[3]:
            out.append(env.reset())
    return out


def _same(a, b) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert len(x) == len(y)
        for u, w in zip(x, y):
            if isinstance(u, np.ndarray):
                np.testing.assert_array_equal(u, w)
            else:
                assert u == w


def test_a_pickled_env_goes_on_with_its_episode_and_its_random_draws():
    env = VisualEnv(load_spec_text(NOISY, "noisy.yaml"))
    env.reset(seed=7)
    env.action_space.seed(3)
    for _ in range(5):
        env.step(env.action_space.sample())
    copy = pickle.loads(pickle.dumps(env))
    assert copy.steps == env.steps == 5 and copy.state == env.state
    assert np.array_equal(copy.action_space.sample(), env.action_space.sample())  # the action space's generator too
    actions = [env.action_space.sample() for _ in range(30)]  # past an episode's end and an unseeded reset
    _same(_run(copy, actions), _run(env, actions))


def test_a_pickled_env_from_make_keeps_its_gymnasium_spec():
    env = visualenv.make("VisualCartPole-v0", render=False)
    env.reset(seed=1)
    env.step(1)
    copy = pickle.loads(pickle.dumps(env))
    assert copy.spec == env.spec and copy.spec is not None
    _same(_run(copy, [0, 1, 1, 0]), _run(env, [0, 1, 1, 0]))


def test_an_env_pickled_before_reset_still_needs_one():
    copy = pickle.loads(pickle.dumps(VisualEnv(load_spec_text(NOISY, "noisy.yaml"))))
    with pytest.raises(ResetNeeded, match="call reset"):
        copy.step(np.zeros(1, np.float32))


def test_a_physics_env_carries_mujocos_state():
    pytest.importorskip("mujoco")
    env = visualenv.make(ROOT / "specs" / "mujoco" / "inverted_pendulum.yaml", render=False)
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(4):
        env.step(env.action_space.sample())
    copy = pickle.loads(pickle.dumps(env))
    actions = [env.action_space.sample() for _ in range(20)]
    _same(_run(copy, actions), _run(env, actions))


def test_an_episode_that_cannot_be_carried_over_says_so():
    pytest.importorskip("mujoco")
    env = visualenv.make(ROOT / "specs" / "mujoco" / "inverted_pendulum.yaml", render=False)
    env.reset(seed=0)
    data = env.__getstate__()
    data["episode"]["physics"] = data["episode"]["physics"][:-1]  # as from a MuJoCo whose state is another size
    copy = VisualEnv.__new__(VisualEnv)
    with pytest.warns(
        RuntimeWarning,
        match=r"the episode it was pickled in could not be carried over \(ValueError: MuJoCo's state has",
    ):
        copy.__setstate__(data)
    with pytest.raises(ResetNeeded, match="could not be carried over"):
        copy.step(copy.action_space.sample())
    copy.reset(seed=0)
    copy.step(copy.action_space.sample())


@pytest.mark.blender
def test_a_rendered_env_goes_on_with_its_frames_and_sensor_noise():
    """The copy's renderer is rebuilt, the scene posed from the carried state, the sensor noise drawn from the carried generator."""
    spec = load_spec_text(
        """\
id: PickledView-v0
scene:
  objects:
    Ball: {primitive: sphere, radius: 0.4, material: {color: [0.9, 0.9, 0.9]}}
    Sun: {light: sun, strength: 3}
    Cam: {camera: perspective, location: [0, -5, 0], look_at: [0, 0, 0]}
state:
  x: {init: "uniform(-1, 1)"}
actions:
  discrete: [{u: -0.3}, {u: 0.3}]
dynamics:
  update: {x: x + u}
actors:
  Ball: {location: [x, 0, 0]}
observation:
  camera: Cam
  resolution: [16, 16]
  color: grayscale
  sensor: {read_noise: 0.05}
max_steps: 10
""",
        "view.yaml",
    )
    env = VisualEnv(spec)
    try:
        env.reset(seed=2)
        env.step(1)
        copy = pickle.loads(pickle.dumps(env))
        try:
            a, b = _run(env, [1, 1, 0]), _run(copy, [1, 1, 0])
            _same(b, a)
            assert np.abs(a[0][0].astype(int) - a[2][0].astype(int)).sum() > 0, "the ball did not move in the picture"
        finally:
            copy.close()
    finally:
        env.close()
