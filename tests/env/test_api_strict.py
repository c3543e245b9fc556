"""The env refuses what it cannot honour: ill-typed actions, step before reset, unknown reset options.

And a registered id takes every documented ``visualenv.make`` option, as
ALE's ids take their preprocessing options: ``gymnasium.make`` and
``gymnasium.make_vec`` build what ``visualenv.make`` builds.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import visualenv

pytestmark = pytest.mark.blender

CARTPOLE = "VisualCartPole-v0"


def _env() -> gym.Env:
    return visualenv.make(CARTPOLE, render=False)


# -- actions ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "action", [1.7, 1.0, "1", True, np.bool_(True), np.float32(1.0), np.array(1.0), np.array([1]), None, [1]]
)
def test_an_action_that_is_not_an_integer_is_refused_naming_the_action_space(action):
    env = _env()
    env.reset(seed=0)
    with pytest.raises(TypeError) as caught:
        env.step(action)
    assert "Discrete(2)" in str(caught.value) and repr(action) in str(caught.value)


@pytest.mark.parametrize("action", [1, np.int64(1), np.int32(1), np.uint8(1), np.array(1), np.array(1, dtype=np.int16)])
def test_integers_numpy_integers_and_0d_integer_arrays_are_accepted(action):
    env = _env()
    env.reset(seed=0)
    reference = _env()
    reference.reset(seed=0)
    assert env.step(action)[4]["state"] == reference.step(1)[4]["state"]


@settings(max_examples=40, deadline=None)
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_no_float_is_taken_as_a_discrete_action(action: float):
    env = _env()
    env.reset(seed=0)
    with pytest.raises(TypeError, match=r"Discrete\(2\)"):
        env.step(action)


def test_a_continuous_action_of_text_is_refused_naming_the_action_space():
    env = visualenv.load_spec_text("""
id: Box-v0
state: {x: {init: 0}}
actions: {continuous: {u: {low: -1, high: 1}}}
dynamics: {update: {x: x + u}}
""")
    env = visualenv.VisualEnv(env)
    env.reset(seed=0)
    with pytest.raises(TypeError, match=r"Box\("):
        env.step(["0.5"])
    assert env.step(np.array([0.5], np.float32))[4]["state"]["x"] == 0.5


def test_step_before_reset_raises_as_gymnasium_order_enforcing_does():
    env = _env()
    with pytest.raises(ResetNeeded, match="reset"):
        env.step(0)
    env.reset(seed=0)
    env.step(0)


# -- reset options ----------------------------------------------------------------------------------


def test_an_unknown_reset_option_is_an_error_listing_the_known_ones():
    env = _env()
    with pytest.raises(ValueError, match=r"unknown reset option 'stat' \(did you mean 'state'\?"):
        env.reset(options={"stat": {"x": 1.0}})


@pytest.mark.parametrize("value", ["abc", "1", True, None, [1.0], float("nan")])
def test_a_bad_state_value_names_the_variable(value):
    env = _env()
    with pytest.raises(ValueError) as caught:
        env.reset(options={"state": {"x": value}})
    assert "options['state']['x']" in str(caught.value), str(caught.value)


def test_good_state_values_are_set():
    env = _env()
    _, info = env.reset(seed=0, options={"state": {"x": 1, "theta": np.float32(0.5)}})
    assert info["state"]["x"] == 1.0 and info["state"]["theta"] == 0.5


# -- gymnasium.make and make_vec take visualenv.make's options ----------------------------------------------


def test_gymnasium_make_takes_the_state_only_options_and_passes_check_env():
    env = gym.make(f"visualenv/{CARTPOLE}", render=False, params={"masscart": 2.0})
    assert env.unwrapped.program.params["masscart"] == 2.0
    check_env(env.unwrapped, skip_render_check=True)


def test_gymnasium_make_refuses_a_bad_option_like_visualenv_make():
    with pytest.raises(visualenv.SpecError, match=r"visualenv.make\(\): frame_stack"):
        gym.make(f"visualenv/{CARTPOLE}", frame_stack=-1)


def test_gymnasium_make_with_image_options_builds_what_visualenv_make_builds():
    options = dict(
        frame_stack=3,
        grayscale=True,
        resize=(32, 24),
        render_mode="rgb_array",
        threads=1,
        samples=1,
        device="cpu",
        engine="cycles",
        readback="auto",
    )
    env = gym.make(f"visualenv/{CARTPOLE}", **options)
    ours = visualenv.make(CARTPOLE, **options)
    try:
        assert env.observation_space == ours.observation_space == gym.spaces.Box(0, 255, (24, 32, 3), np.uint8)
        check_env(env)
        a, _ = env.reset(seed=1)
        b, _ = ours.reset(seed=1)
        np.testing.assert_array_equal(a, b)
        assert a.std() > 0, "a blank observation"
        assert env.render().shape[2] == 3
    finally:
        env.close()
        ours.close()


def test_gymnasium_make_vec_takes_the_options():
    vec = gym.make_vec(
        f"visualenv/{CARTPOLE}", num_envs=2, vectorization_mode="sync", frame_stack=2, resize=(16, 16), threads=1
    )
    try:
        obs, _ = vec.reset(seed=0)
        assert obs.shape == (2, 16, 16, 2)
        obs, *_ = vec.step(np.array([0, 1]))
        assert obs.shape == (2, 16, 16, 2)
    finally:
        vec.close()
