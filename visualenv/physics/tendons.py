"""Tendons as MuJoCo draws them: a capsule along each segment of the path, and a slack string as a hanging curve.

MuJoCo's renderer (``mjv_updateScene``) draws a tendon through two sites that only a length limit holds (no spring,
damping, friction loss or actuator, under gravity) as a catenary of the limit's length while it is slack: ball_in_cup's
string hangs below the cup until the ball pulls it straight. :func:`tendon_path` computes the same points, so a
renderer draws the same curve from the sites' world positions every step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: MuJoCo's actuator transmission type (mjtTrn) of an actuator that pulls a tendon
TRN_TENDON = 3
#: Newton's tolerance in MuJoCo's catenary solve
_TOLERANCE = 1e-9


@dataclass(frozen=True)
class TendonShape:
    """A spatial tendon MuJoCo draws: capsules of radius `width` along its path, here through sites only; each point is
    a site's body and its position in that body's frame, so its world place follows the bodies."""

    name: str  # tendon:<name>
    width: float
    rgba: tuple[float, float, float, float]
    points: tuple[tuple[int, tuple[float, float, float]], ...]
    #: the length a slack string hangs at (None: drawn straight between its points)
    hanging: float | None = None
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    #: points along a hanging string (MuJoCo's numslices + 1, at most 100)
    slices: int = 29
    emission: float = 0.0
    specular: float = 0.5
    shininess: float = 0.5

    @property
    def segments(self) -> int:
        """The most segments its path has: one less than its points, or than a hanging curve's."""
        return self.slices - 1 if self.hanging is not None else len(self.points) - 1


def catenary_length(model: Any, i: int) -> float | None:
    """The length tendon i hangs at while slack, as ``mjv_isCatenary`` decides it; None where MuJoCo draws it straight."""
    from visualenv.physics.model import mujoco_module

    mujoco = mujoco_module()
    stiff = _nonzero(model, "tendon_stiffness", i) or _nonzero(model, "tendon_stiffnesspoly", i)
    damped = _nonzero(model, "tendon_damping", i) or _nonzero(model, "tendon_dampingpoly", i)
    lower, upper = (float(v) for v in model.tendon_range[i])
    spring_lo, spring_hi = (float(v) for v in model.tendon_lengthspring[i])
    spring = stiff and spring_lo == 0 and spring_hi > 0
    limit = not stiff and bool(model.tendon_limited[i]) and lower == 0
    gravity = not (int(model.opt.disableflags) & int(mujoco.mjtDisableBit.mjDSBL_GRAVITY))
    pulled = any(
        int(model.actuator_trntype[j]) == TRN_TENDON and int(model.actuator_trnid[j][0]) == i for j in range(model.nu)
    )
    if (
        not gravity
        or float(np.linalg.norm(model.opt.gravity)) <= 1e-15
        or int(model.tendon_num[i]) != 2
        or spring == limit
        or damped
        or float(model.tendon_frictionloss[i]) != 0
        or pulled
    ):
        return None
    return upper if limit else spring_hi


def _nonzero(model: Any, field: str, i: int) -> bool:
    """Whether tendon i's `field` is set (a field this MuJoCo lacks is not)."""
    values = getattr(model, field, None)
    return values is not None and bool(np.any(values[i]))


def tendon_path(tendon: TendonShape, points: np.ndarray) -> np.ndarray:
    """The points MuJoCo draws the tendon through, given its sites' world positions (k, 3): a hanging string's curve
    while slack (the points of ``mjv_catenary``), else the sites themselves."""
    if tendon.hanging is None:
        return points
    return catenary(points[0], points[1], np.asarray(tendon.gravity, dtype=float), tendon.hanging, tendon.slices)


def catenary(x0: np.ndarray, x1: np.ndarray, gravity: np.ndarray, length: float, count: int) -> np.ndarray:
    """A string of `length` hung from `x0` to `x1` under `gravity`, as MuJoCo draws it: straight where it is taut (2
    points), a bead's 3 points where it hangs nearly vertically, else `count` points of the catenary."""
    x01 = x1 - x0
    if float(np.linalg.norm(x01)) > length:
        return np.stack([x0, x1])
    up = -gravity / np.linalg.norm(gravity)
    across = x01 - up * float(up @ x01)
    norm = float(np.linalg.norm(across))
    across = across / norm if norm >= 1e-15 else np.zeros(3)
    h, v = float(x01 @ across), float(x01 @ up)
    if length > 100 * h:  # the bead where a nearly vertical string hangs
        down = -0.5 * (math.sqrt(length * length - h * h) - v)
        bead = x0 + up * down + across * (h * down / (2 * down - v))
        return np.stack([x0, bead, x1])
    bh = _flatness(v, h, length) * h
    h_offset = -0.5 * (math.log((length + v) / (length - v)) * bh - h)
    v_offset = -math.cosh(h_offset / bh) * bh
    out = np.empty((count, 3))
    out[0], out[-1] = x0, x1
    for i in range(1, count - 1):  # MuJoCo spaces them by h / count (its last step to x1 is longer)
        horizontal = i * h / count
        out[i] = x0 + across * horizontal + up * (bh * math.cosh((horizontal - h_offset) / bh) + v_offset)
    return out


def _flatness(v: float, h: float, length: float) -> float:
    """The catenary's scaled flatness b, by Newton's method on the transcendental equation (as MuJoCo solves it)."""
    intercept = 1 / math.sqrt(math.sqrt(length * length - v * v) / h - 1)

    def residual(b: float) -> tuple[float, float]:
        a = 0.5 / b
        sinh, cosh = math.sinh(a), math.cosh(a)
        return 1 / math.sqrt(2 * b * sinh - 1) - intercept, (a * cosh - sinh) * (2 * b * sinh - 1) ** -1.5

    def size(b: float) -> float:  # how far b is from a root; a step out of the domain is no better
        try:
            return abs(residual(b)[0]) if b > 0 else math.inf
        except (ValueError, OverflowError, ZeroDivisionError):
            return math.inf

    b = intercept / math.sqrt(24)
    for _ in range(50):
        res, grad = residual(b)
        if abs(res) < _TOLERANCE:
            break
        step = -res / grad
        for _ in range(10):  # backtracking
            if size(b + step) < abs(res):
                break
            step *= 0.5
        b += step
    return b
