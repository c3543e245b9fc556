"""tolerance() in the expression language equals dm_control.utils.rewards.tolerance, for every sigmoid it offers.

Each case runs through the checker and the generated code (as a reward would), and through the
batch's numpy version, and is compared with dm_control's own function on the same arguments. The
two agree to 1e-12 (numpy's own exp/log may differ from the C library's in the last bit, on some
CPUs); the batch version equals the scalar one exactly.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from visualenv.compiler.batch_step import vector_globals
from visualenv.errors import ExpressionError
from visualenv.expr import NUM, check
from visualenv.expr.codegen import FunctionBuilder, Site, function_globals, local, lower, name
from visualenv.expr.tolerance import SIGMOIDS, tolerance, tolerance_columns

rewards = pytest.importorskip("dm_control.utils.rewards")

XS = [
    -1e300,
    -40.0,
    -5.5,
    -2.0,
    -1.0,
    -0.75,
    -0.5,
    -0.1,
    -1e-9,
    0.0,
    1e-9,
    0.1,
    0.3,
    0.5,
    0.999,
    1.0,
    1.001,
    1.5,
    2.0,
    3.7,
    10.0,
    1e3,
    1e300,
    math.inf,
    -math.inf,
]
BOUNDS = [(0.0, 0.0), (-0.25, 0.25), (0.5, math.inf), (-math.inf, -0.5), (1.0, 1.0), (-math.inf, math.inf)]
MARGINS = [0.0, 0.3, 1.0, 2.0, 5.0]
VALUES = [0.0, 1e-3, 0.1, 0.5, 0.9]


def compiled(text: str):
    """The expression as the compiler builds a reward: checked, lowered, one generated function of x."""
    checked = check(text, {"x": NUM})
    fb = FunctionBuilder("f", [local("x")])
    fb.assign("_r", lower(checked.tree), Site("reward", text))
    fb.returns(name("_r"))
    return fb.build(function_globals())


def theirs(x: float, bounds: tuple, margin: float, sigmoid: str, value: float) -> float:
    with np.errstate(all="ignore"):
        return float(rewards.tolerance(x, bounds=bounds, margin=margin, sigmoid=sigmoid, value_at_margin=value))


@pytest.mark.parametrize("sigmoid", SIGMOIDS)
def test_tolerance_equals_dm_controls_for_every_sigmoid(sigmoid: str) -> None:
    compared = 0
    for bounds, margin, value in itertools.product(BOUNDS, MARGINS, VALUES):
        if margin > 0 and (value == 0.0 and sigmoid not in ("cosine", "linear", "quadratic")):
            continue  # dm_control refuses it (tested below)
        lo, hi = (repr(b) if math.isfinite(b) else ("-inf" if b < 0 else "inf") for b in bounds)
        f = compiled(
            f'tolerance(x, bounds=[{lo}, {hi}], margin={margin!r}, sigmoid="{sigmoid}", value_at_margin={value!r})'
        )
        ours = [f(x) for x in XS]
        expected = [theirs(x, bounds, margin, sigmoid, value) for x in XS]
        assert all(type(v) is float for v in ours)
        np.testing.assert_allclose(
            ours, expected, rtol=0, atol=1e-12, err_msg=f"{sigmoid} {bounds} margin {margin} value {value}"
        )
        batch = tolerance_columns(np.array(XS), bounds, margin, float(SIGMOIDS.index(sigmoid)), value)
        assert batch.tobytes() == np.array(ours).tobytes()  # the batch calls the same code: equal to the bit
        compared += len(XS)
    assert compared > 500


def test_defaults_and_positional_form_are_dm_controls() -> None:
    """tolerance(x) is dm_control's defaults (bounds (0, 0), margin 0, gaussian, 0.1); the positional form is its order."""
    for x in XS:
        assert compiled("tolerance(x)")(x) == theirs(x, (0.0, 0.0), 0.0, "gaussian", 0.1)
        assert compiled("tolerance(x, margin=2)")(x) == pytest.approx(
            theirs(x, (0.0, 0.0), 2.0, "gaussian", 0.1), abs=1e-12
        )
        assert compiled('tolerance(x, [0, 1], 2, "quadratic", 0)')(x) == theirs(x, (0.0, 1.0), 2.0, "quadratic", 0.0)


def test_cartpole_terms_are_dm_controls() -> None:
    """The three tolerance() calls of cartpole's smooth reward, on the values an episode sees."""
    rng = np.random.default_rng(0)
    control = compiled('tolerance(x, margin=1, value_at_margin=0, sigmoid="quadratic")')
    velocity, centred = compiled("tolerance(x, margin=5)"), compiled("tolerance(x, margin=2)")
    for x in rng.uniform(-12, 12, 2000):
        assert control(x) == theirs(x, (0, 0), 1, "quadratic", 0)
        assert velocity(x) == pytest.approx(theirs(x, (0, 0), 5, "gaussian", 0.1), abs=1e-12)
        assert centred(x) == pytest.approx(theirs(x, (0, 0), 2, "gaussian", 0.1), abs=1e-12)


def test_generated_batch_code_calls_the_columns_version() -> None:
    checked = check('tolerance(x, margin=1, sigmoid="linear", value_at_margin=0)', {"x": NUM})
    fb = FunctionBuilder("f", [local("x")])
    fb.assign("_r", lower(checked.tree))
    fb.returns(name("_r"))
    from visualenv.compiler.batch_step import vectorize

    f = vectorize(fb)
    assert f is not None and "_f_tolerance" in vector_globals()
    xs = np.linspace(-3, 3, 61)
    np.testing.assert_array_equal(f(xs), [tolerance(x, (0.0, 0.0), 1.0, 5.0, 0.0) for x in xs])


@pytest.mark.parametrize(
    "text, message",
    [
        ("tolerance(x, [1, 0])", "lower <= upper"),
        ("tolerance(x, margin=-1)", "margin >= 0"),
        ("tolerance(x, margin=1, value_at_margin=0)", "0 < value_at_margin < 1"),
        ('tolerance(x, margin=1, sigmoid="linear", value_at_margin=1)', "0 <= value_at_margin < 1"),
        ('tolerance(x, margin=1, sigmoid="gausian")', "did you mean 'gaussian'"),
        ("tolerance(x, margin=1, sigmoid=gaussian)", "written in quotes"),
        ("tolerance(x, marign=1)", "did you mean 'margin'"),
        ("tolerance(x, 1, 2)", "'bounds' of tolerance() needs a vector of 2"),
        ("tolerance(x, margin=1, margin=2)", "two values for 'margin'"),
        ("tolerance(margin=1)", "needs 'x'"),
        ('tolerance(x, [0, 0], 1, "gaussian", 0.1, 2)', "at most 5 arguments"),
        ("sin(x=1)", "takes no keyword arguments"),
        ('sin("gaussian")', "text values are not allowed"),
    ],
)
def test_arguments_dm_control_refuses_fail_at_check(text: str, message: str) -> None:
    """What dm_control raises at run time, a constant argument raises when the spec is checked, located."""
    with pytest.raises(ExpressionError) as caught:
        check(text, {"x": NUM})
    assert message in caught.value.message
    if message.startswith(("lower", "margin", "0 ")):
        with pytest.raises(ValueError):  # and dm_control refuses the same
            rewards.tolerance(
                0.5,
                bounds=(1, 0) if "[1, 0]" in text else (0, 0),
                margin=-1 if "-1" in text else 1,
                sigmoid="linear" if "linear" in text else "gaussian",
                value_at_margin=1 if "linear" in text else 0,
            )


def test_arguments_known_only_at_run_time_fault_there() -> None:
    """A margin computed from the state can be negative: the scalar code raises (a located fault), the batch gives NaN."""
    checked = check("tolerance(x, margin=x)", {"x": NUM})
    fb = FunctionBuilder("f", [local("x")])
    fb.assign("_r", lower(checked.tree))
    fb.returns(name("_r"))
    f = fb.build(function_globals())
    assert f(1.0) == pytest.approx(theirs(1.0, (0, 0), 1.0, "gaussian", 0.1))
    with pytest.raises(ValueError, match="margin >= 0"):
        f(-1.0)
    assert np.isnan(tolerance_columns(np.array([-1.0]), (0.0, 0.0), np.array([-1.0]), 0.0, 0.1)[0])
