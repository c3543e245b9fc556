"""Runtime faults in state-only envs: loud and located, or a clean episode end.

A state that becomes NaN or infinite, a division by zero or a math domain error
in a step raises :class:`visualenv.StepError` naming the expression, its spec
line and the values it read; with ``on_fault: terminate`` the episode ends
with ``info["error"]`` instead. An observation never silently holds NaN or inf.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import visualenv
from visualenv import StepError, VisualEnv, load_spec_text

TEMPLATE = """\
id: Faults-v0
params:
  k: 2
state:
  x: {{init: "{init}"}}
  v: {{init: 0}}
  hidden: {{init: 0, observe: false}}
actions:
  discrete:
    - {{u: 0}}
    - {{u: 1}}
dynamics:
  let:
    a: {let}
  update:
    x: {update}
    v: v + u
    hidden: {hidden}
reward: {reward}
outcomes:
  far: {{when: "abs(x) > 1e300"}}
on_fault: {on_fault}
"""
#: 1-based spec lines of the expressions above
LINES = {"state.x.init": 5, "dynamics.let.a": 14, "dynamics.update.x": 16, "dynamics.update.hidden": 18, "reward": 19}


def make(*, init="1", let="x", update="x + a * 0", hidden="hidden", reward="1", on_fault="raise") -> VisualEnv:
    text = TEMPLATE.format(init=init, let=let, update=update, hidden=hidden, reward=reward, on_fault=on_fault)
    return VisualEnv(load_spec_text(text, "faults.yaml"), render=False)


def step_until_fault(env: VisualEnv, action: int = 1, limit: int = 50) -> StepError:
    env.reset(seed=0)
    for _ in range(limit):
        try:
            obs, reward, *_ = env.step(action)
        except StepError as exc:
            return exc
        assert np.isfinite(obs).all() and math.isfinite(reward), "a non-finite value got through silently"
    raise AssertionError("no fault")


# (fields for make(), the expression that must be named, a message fragment, values that must be shown)
FAULTS = [
    pytest.param({"update": "x / (v - 1)"}, "dynamics.update.x", "division by zero", ["v=1.0"], id="division-by-zero"),
    pytest.param({"let": "1 / (v - 2)"}, "dynamics.let.a", "division by zero", ["v=2.0"], id="division-by-zero-in-let"),
    pytest.param({"update": "x % (v - 1)"}, "dynamics.update.x", "division by zero", ["v=1.0"], id="modulo-by-zero"),
    pytest.param({"update": "sqrt(1 - v)"}, "dynamics.update.x", "math domain error", ["v=2.0"], id="sqrt-of-negative"),
    pytest.param({"update": "log(1 - v)"}, "dynamics.update.x", "math domain error", ["v=1.0"], id="log-of-zero"),
    pytest.param({"update": "acos(v)"}, "dynamics.update.x", "math domain error", ["v=2.0"], id="acos-out-of-domain"),
    pytest.param(
        {"update": "(v - 2) ** 0.5"},
        "dynamics.update.x",
        "a negative number to a fractional power",
        ["v=0.0"],
        id="negative-fractional-power",
    ),
    pytest.param({"update": "exp(x * 1000)"}, "dynamics.update.x", "numeric overflow", ["x=1.0"], id="exp-overflow"),
    pytest.param(
        {"update": "x * 1e300 * 1e300"}, "dynamics.update.x", "state 'x' became inf", ["x=1.0"], id="state-becomes-inf"
    ),
    pytest.param(
        {"update": "x * 1e200"},
        "dynamics.update.x",
        "too large for the float32 observation",
        ["x=1.0"],
        id="state-overflows-float32",
    ),
    pytest.param(
        {"update": "x * 1e300 * 1e300", "init": "-1"},
        "dynamics.update.x",
        "state 'x' became -inf",
        ["x=-1.0"],
        id="state-becomes-minus-inf",
    ),
    pytest.param(
        {"update": "x * inf - x * inf"}, "dynamics.update.x", "state 'x' became nan", ["x=1.0"], id="state-becomes-nan"
    ),
    pytest.param(
        {"hidden": "hidden + 1e300 * v * 1e10"},
        "dynamics.update.hidden",
        "state 'hidden' became inf",
        ["v=1.0"],
        id="unobserved-state-becomes-inf",
    ),
    pytest.param({"reward": "1e300 * (v + 1) * 1e10"}, "reward", "the reward became inf", [], id="reward-becomes-inf"),
    pytest.param({"reward": "x * inf - x * inf"}, "reward", "the reward became nan", [], id="reward-becomes-nan"),
]


@pytest.mark.parametrize("fields, where, message, shown", FAULTS)
def test_fault_raises_step_error_naming_expression_line_and_values(fields, where, message, shown):
    err = step_until_fault(make(**fields))
    text = str(err)
    expression = fields.get(
        {
            "dynamics.let.a": "let",
            "dynamics.update.x": "update",
            "dynamics.update.hidden": "hidden",
            "reward": "reward",
        }[where]
    )
    assert f"faults.yaml:{LINES[where]}: {where} = {expression!r}: " in text, text
    assert message in text, text
    assert "values: " in text
    for value in shown:
        assert value in text, text


@pytest.mark.parametrize("fields, where, message, shown", FAULTS)
def test_on_fault_terminate_ends_the_episode_with_info_error(fields, where, message, shown):
    env = make(on_fault="terminate", **fields)
    obs, _ = env.reset(seed=0)
    for _ in range(50):
        before = env.state
        obs, reward, terminated, truncated, info = env.step(1)
        assert np.isfinite(obs).all() and math.isfinite(reward)
        if "error" in info:
            break
    else:
        raise AssertionError("no fault")
    assert terminated and not truncated and reward == 0.0
    assert info["outcome"] == "error"
    assert where in info["error"] and message in info["error"]
    assert env.state == before, "the faulty state is not committed"
    np.testing.assert_array_equal(obs, np.array([before["x"], before["v"]], np.float32))
    # the env is usable again after a reset
    obs, _ = env.reset(seed=1)
    assert np.isfinite(obs).all()


@pytest.mark.parametrize(
    "init, message",
    [
        ("1 / (k - 2)", "division by zero"),  # k is a param: folded, so caught when the spec compiles
        ("inf", "state 'x' is inf at reset"),
        ("-inf", "state 'x' is -inf at reset"),
        ("normal(0, inf)", "at reset"),
        ("uniform(1e39, 1e39)", "too large for the float32 observation"),
        ("randint(2, 1)", "needs low <= high"),  # constant arguments: caught when the spec is compiled
        ("normal(0, -1)", "needs std >= 0"),
    ],
)
def test_faults_at_reset_raise_step_error(init, message):
    if init in ("1 / (k - 2)", "randint(2, 1)", "normal(0, -1)"):
        with pytest.raises(visualenv.SpecError, match=re.escape(message)):
            make(init=init)  # constant: caught when the spec is compiled
        return
    env = make(init=init)
    with pytest.raises(StepError) as err:
        env.reset(seed=0)
    assert message in str(err.value)
    assert "faults.yaml:5: state.x.init" in str(err.value)


def test_on_fault_terminate_does_not_hide_reset_faults():
    env = make(init="inf", on_fault="terminate")
    with pytest.raises(StepError, match="at reset"):
        env.reset(seed=0)


def test_no_fault_no_error_key():
    env = make(on_fault="terminate")
    env.reset(seed=0)
    for _ in range(5):
        obs, reward, terminated, truncated, info = env.step(1)
        assert "error" not in info and not terminated
        assert np.isfinite(obs).all()


def test_state_that_only_approaches_the_limit_is_fine():
    env = make(update="x * 10", init="1")
    env.reset(seed=0)
    for _ in range(38):
        obs, *_ = env.step(0)
    assert obs[0] == np.float32(1e38)
    with pytest.raises(StepError, match="too large for the float32 observation"):
        env.step(0)


def test_step_error_is_a_visualenv_error_and_the_message_is_one_line():
    err = step_until_fault(make(update="x / (v - 1)"))
    assert isinstance(err, visualenv.VisualEnvError)
    assert "\n" not in str(err)
    assert err.__cause__ is None and err.__suppress_context__, "raised 'from None': the user sees only the StepError"


BOUND = """\
id: Bound-v0
scene:
  objects:
    Box: {primitive: cube}
state:
  x: {init: 0}
actions: {discrete: [{u: 1}]}
dynamics: {update: {x: x + u}}
actors:
  Box: {location: ["1 / (x - 1)", 0, "x * inf if x < 0.5 else 0"], visible: x < 5}
"""


def test_fault_in_an_actor_binding_is_a_step_error_naming_the_binding():
    env = VisualEnv(load_spec_text(BOUND, "bound.yaml"), render=False)
    env.reset(seed=0)
    with pytest.raises(StepError, match=r"bound\.yaml:10: actors\.Box\.location = .*a binding became nan .*x=0\.0"):
        env.binding_values()  # x * inf with x = 0
    env.step(0)
    with pytest.raises(StepError, match=r"bound\.yaml:10: actors\.Box\.location = .*division by zero .*x=1\.0"):
        env.binding_values()
    env.step(0)
    assert env.binding_values() == (1.0, 0.0, 0.0, True)


AFTER_A_VECTOR = """\
id: After-v0
scene:
  objects:
    Box: {primitive: cube}
    Lamp: {light: point}
state:
  x: {init: 0}
actions: {discrete: [{u: 1}]}
dynamics: {update: {x: x + u}}
actors:
  Box: {location: "[x, 0, 1] if x < 3 else [0, 0, 0]"}
  Lamp: {strength: x * inf}
"""


def test_a_binding_fault_after_a_vector_binding_names_its_own_binding():
    # Box's location is one vector expression (its own generated line) before its three values: Lamp's value is the 4th
    env = VisualEnv(load_spec_text(AFTER_A_VECTOR, "after.yaml"), render=False)
    env.reset(seed=0)
    env.step(0)
    with pytest.raises(
        StepError, match=r"after\.yaml:12: actors\.Lamp\.strength = 'x \* inf': a binding became inf .*x=1\.0"
    ):
        env.binding_values()


SEEN = """\
id: Seen-v0
scene:
  objects:
    Box: {primitive: cube}
    Cam: {camera: perspective, location: [0, -8, 0], look_at: [0, 0, 0]}
state:
  x: {init: 0}
actions: {discrete: [{u: 1}]}
dynamics: {update: {x: x + u}}
actors:
  Box: {location: ["1 / (x - 1)", 0, 0]}
observation: {camera: Cam, resolution: [16, 16], color: grayscale}
render: {engine: cycles, preset: fast}
on_fault: ON_FAULT
"""


@pytest.mark.blender
def test_a_binding_fault_while_rendering_obeys_on_fault():
    # x becomes 1 at the first step, so the Box's location divides by zero before the observation is rendered
    env = VisualEnv(load_spec_text(SEEN.replace("ON_FAULT", "terminate"), "seen.yaml"))
    first, _ = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(0)
    assert terminated and not truncated and reward == 0.0
    assert "seen.yaml:11: actors.Box.location" in info["error"] and "division by zero" in info["error"]
    assert obs.shape == first.shape and np.array_equal(obs, first), "the last frame that could be rendered"
    env.close()
    env = VisualEnv(load_spec_text(SEEN.replace("ON_FAULT", "raise"), "seen.yaml"))
    env.reset(seed=0)
    with pytest.raises(StepError, match=r"seen\.yaml:11: actors\.Box\.location = .*division by zero"):
        env.step(0)
    env.close()
