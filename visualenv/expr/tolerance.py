"""dm_control's ``tolerance()``: 1 inside the bounds, falling off outside them by one of eight sigmoids.

DeepMind Control's rewards are products of these soft indicators
(``dm_control.utils.rewards.tolerance``). This is the same function on one
number, written with Python's ``math`` so a spec's reward computes what
dm_control computes (to the last bit where numpy and the C library agree; at
most an ulp of ``exp``/``log`` apart where numpy uses its own vector code),
and its element-wise form for batches, which calls the same scalar code so a
batch equals its envs alone to the bit.

The sigmoid is an index into :data:`SIGMOIDS` here: the expression checker
turns the text a spec writes (``sigmoid="quadratic"``) into that constant.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: dm_control's sigmoids, in the order their indices stand for them
SIGMOIDS = ("gaussian", "hyperbolic", "long_tail", "reciprocal", "cosine", "linear", "quadratic", "tanh_squared")
#: dm_control's default value at the margin
DEFAULT_VALUE_AT_MARGIN = 0.1
#: sigmoids that may reach 0 at the margin (the others only approach it)
_REACH_ZERO = ("cosine", "linear", "quadratic")


def problem(lower: float, upper: float, margin: float, sigmoid: str, value_at_margin: float) -> str | None:
    """Why these arguments cannot work, in dm_control's terms (None when they can): bounds order, margin sign, value range."""
    if lower > upper:
        return f"tolerance() needs bounds [lower, upper] with lower <= upper, got [{lower:g}, {upper:g}]"
    if margin < 0:
        return f"tolerance() needs margin >= 0, got {margin:g}"
    if margin > 0:  # dm_control checks value_at_margin only where a margin uses it
        if sigmoid in _REACH_ZERO and not 0 <= value_at_margin < 1:
            return f"tolerance() with sigmoid '{sigmoid}' needs 0 <= value_at_margin < 1, got {value_at_margin:g}"
        if sigmoid not in _REACH_ZERO and not 0 < value_at_margin < 1:
            return f"tolerance() with sigmoid '{sigmoid}' needs 0 < value_at_margin < 1, got {value_at_margin:g}"
    return None


def _sech(t: float) -> float:
    try:
        return 1 / math.cosh(t)
    except OverflowError:  # numpy's cosh is inf there, and 1 / inf is 0
        return 0.0


def sigmoid_value(d: float, value_at_1: float, sigmoid: str) -> float:
    """dm_control's ``_sigmoids``: 1 at d = 0, `value_at_1` at d = 1, the same arithmetic in the same order."""
    if sigmoid == "gaussian":
        scale = math.sqrt(-2 * math.log(value_at_1))
        t = d * scale
        return math.exp(-0.5 * (t * t))
    if sigmoid == "hyperbolic":
        return _sech(d * math.acosh(1 / value_at_1))
    if sigmoid == "long_tail":
        t = d * math.sqrt(1 / value_at_1 - 1)
        return 1 / (t * t + 1)
    if sigmoid == "reciprocal":
        return 1 / (abs(d) * (1 / value_at_1 - 1) + 1)
    if sigmoid == "cosine":
        s = d * (math.acos(2 * value_at_1 - 1) / math.pi)
        return (1 + math.cos(math.pi * s)) / 2 if abs(s) < 1 else 0.0
    if sigmoid == "linear":
        s = d * (1 - value_at_1)
        return 1 - s if abs(s) < 1 else 0.0
    if sigmoid == "quadratic":
        s = d * math.sqrt(1 - value_at_1)
        return 1 - s * s if abs(s) < 1 else 0.0
    t = math.tanh(d * math.atanh(math.sqrt(1 - value_at_1)))  # tanh_squared
    return 1 - t * t


def tolerance(
    x: float,
    bounds: tuple[float, float] = (0.0, 0.0),
    margin: float = 0.0,
    sigmoid: float = 0.0,
    value_at_margin: float = DEFAULT_VALUE_AT_MARGIN,
) -> float:
    """``dm_control.utils.rewards.tolerance(x, bounds, margin, SIGMOIDS[sigmoid], value_at_margin)`` for one number.

    ValueError, with dm_control's reason, for arguments it refuses (the env reports it located).
    """
    lower, upper = bounds
    name = SIGMOIDS[int(sigmoid)]
    why = problem(lower, upper, margin, name, value_at_margin)
    if why:
        raise ValueError(why)
    in_bounds = lower <= x <= upper
    if margin == 0:
        return 1.0 if in_bounds else 0.0
    if in_bounds:
        return 1.0
    d = (lower - x if x < lower else x - upper) / margin
    return float(sigmoid_value(d, value_at_margin, name))


def _tolerance_or_nan(
    x: float, lower: float, upper: float, margin: float, sigmoid: float, value_at_margin: float
) -> float:
    try:
        return tolerance(x, (lower, upper), margin, sigmoid, value_at_margin)
    except (ValueError, ArithmeticError):  # the env whose arguments fail steps again alone, and raises there, located
        return math.nan


_ELEMENTWISE = np.frompyfunc(_tolerance_or_nan, 6, 1)


def tolerance_columns(
    x: Any,
    bounds: tuple[Any, Any] = (0.0, 0.0),
    margin: Any = 0.0,
    sigmoid: Any = 0.0,
    value_at_margin: Any = DEFAULT_VALUE_AT_MARGIN,
) -> np.ndarray:
    """:func:`tolerance` on columns (one value per env): the scalar code per element, so a batch equals its envs alone.

    An env whose arguments dm_control would refuse gets NaN: a batch steps such an env again
    alone, which raises the located fault.
    """
    lower, upper = bounds
    # Python's float arithmetic overflowing to inf, as dm_control's numpy does, silently
    with np.errstate(all="ignore"):
        return np.asarray(_ELEMENTWISE(x, lower, upper, margin, sigmoid, value_at_margin), dtype=np.float64)
