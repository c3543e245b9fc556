"""The fixed table of functions an expression may call.

Each entry says how many arguments it takes, of which types, what it returns
and which Python callable implements it. Random draws take their generator
from the env (seeded by ``reset(seed=...)``), so they are bound per env by
:func:`bind_random`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from visualenv.expr.tolerance import DEFAULT_VALUE_AT_MARGIN, SIGMOIDS, tolerance
from visualenv.expr.types import NUM, Type, vec


def _sign(x: float) -> float:
    return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)


def _clip(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else (hi if x > hi else x)


def _log(x: float, base: float | None = None) -> float:
    return math.log(x) if base is None else math.log(x, base)


def _floor(x: float) -> float:
    return float(math.floor(x))


def _ceil(x: float) -> float:
    return float(math.ceil(x))


def _round(x: float) -> float:
    return float(round(x))


def _min(*args: Any) -> float:
    return float(min(args[0]) if len(args) == 1 else min(args))


def _max(*args: Any) -> float:
    return float(max(args[0]) if len(args) == 1 else max(args))


@dataclass(frozen=True)
class Param:
    """A named parameter of a function that takes keyword arguments (``tolerance(x, margin=2)``).

    ``choices``: the parameter is text in quotes, one of these; the checker passes its index on as a number.
    """

    name: str
    type: Type = NUM
    default: Any = None  # None: required; a number, a tuple (a vector literal) or, with choices, one of them
    choices: tuple[str, ...] = ()


@dataclass(frozen=True)
class Function:
    name: str
    impl: Callable[..., Any] | None  # None: bound per env (random draws)
    min_args: int
    max_args: int | None  # None: any number
    arg_type: Type  # every argument has this type (VEC: any vector)
    returns: Type
    random: bool = False
    doc: str = ""
    params: tuple[Param, ...] = ()  # set: the arguments are these, by position or keyword (each with its own type)


def _f(
    name: str,
    impl: Callable[..., Any] | None,
    n: int | tuple[int, int | None],
    doc: str,
    *,
    arg: Type = NUM,
    returns: Type = NUM,
    random: bool = False,
) -> Function:
    lo, hi = (n, n) if isinstance(n, int) else n
    return Function(name, impl, lo, hi, arg, returns, random, doc)


FUNCTIONS: dict[str, Function] = {
    f.name: f
    for f in [
        _f("sin", math.sin, 1, "sine (radians)"),
        _f("cos", math.cos, 1, "cosine (radians)"),
        _f("tan", math.tan, 1, "tangent (radians)"),
        _f("asin", math.asin, 1, "arc sine"),
        _f("acos", math.acos, 1, "arc cosine"),
        _f("atan", math.atan, 1, "arc tangent"),
        _f("atan2", math.atan2, 2, "atan2(y, x): angle of (x, y)"),
        _f("sinh", math.sinh, 1, "hyperbolic sine"),
        _f("cosh", math.cosh, 1, "hyperbolic cosine"),
        _f("tanh", math.tanh, 1, "hyperbolic tangent"),
        _f("asinh", math.asinh, 1, "inverse hyperbolic sine (dm_control's np.arcsinh: quadruped's force sensors)"),
        _f("sqrt", math.sqrt, 1, "square root"),
        _f("exp", math.exp, 1, "e to the power x"),
        _f("log", _log, (1, 2), "natural log, or log(x, base)"),
        _f("log1p", math.log1p, 1, "log(1 + x), exact for x near 0 (dm_control's np.log1p)"),
        _f("abs", abs, 1, "absolute value"),
        _f("min", _min, (2, None), "smallest argument"),
        _f("max", _max, (2, None), "largest argument"),
        _f("clip", _clip, 3, "clip(x, low, high)"),
        _f("hypot", math.hypot, (2, 3), "Euclidean length of (x, y[, z])"),
        _f("floor", _floor, 1, "round down"),
        _f("ceil", _ceil, 1, "round up"),
        _f("round", _round, 1, "round to nearest (ties to even)"),
        _f("sign", _sign, 1, "-1, 0 or 1"),
        _f("radians", math.radians, 1, "degrees to radians"),
        _f("degrees", math.degrees, 1, "radians to degrees"),
        _f("uniform", None, 2, "uniform(low, high): a random number in [low, high)", random=True),
        _f("normal", None, 2, "normal(mean, std): a Gaussian random number", random=True),
        _f("randint", None, 2, "randint(low, high): a random integer in [low, high], both included", random=True),
        _f(
            "choice",
            None,
            (1, None),
            "choice(a, b, ...) or choice([a, b, ...]): one of the values at random",
            random=True,
        ),
        Function(
            "tolerance",
            tolerance,
            1,
            5,
            NUM,
            NUM,
            doc='tolerance(x, bounds=[lower, upper], margin=0, sigmoid="gaussian", '
            "value_at_margin=0.1): dm_control's soft indicator, 1 inside the bounds and falling off outside them",
            params=(
                Param("x"),
                Param("bounds", vec(2), (0.0, 0.0)),
                Param("margin", NUM, 0.0),
                Param("sigmoid", NUM, "gaussian", SIGMOIDS),
                Param("value_at_margin", NUM, DEFAULT_VALUE_AT_MARGIN),
            ),
        ),
        _f(
            "uniform_disk",
            None,
            1,
            "uniform_disk(r): a point [x, y] uniform in the disk of radius r (pairs drawn in the square "
            "until one falls inside, as Gymnasium's Reacher draws its goal)",
            returns=vec(2),
            random=True,
        ),
        _f(
            "random_quaternion",
            None,
            0,
            "random_quaternion(): a unit quaternion [w, x, y, z] uniform over rotations (four normal(0, 1) draws, "
            "normalised, as dm_control draws an unlimited ball joint)",
            returns=vec(4),
            random=True,
        ),
        _f(
            "random_quaternion_positive",
            None,
            0,
            "random_quaternion_positive(): a unit quaternion [w, x, y, z] of four uniform(0, 1) draws, normalised: "
            "every part positive, not uniform over rotations (as dm_control draws a free joint's orientation)",
            returns=vec(4),
            random=True,
        ),
    ]
}

#: named constants every expression can use
#: ('tau' is left out on purpose: it is a common parameter name, a time step)
CONSTANTS: dict[str, float] = {"pi": math.pi, "e": math.e, "inf": math.inf}


class RandomSource:
    """Random draws for expressions, reading the env's current seeded generator.

    The generator is numpy's ``Generator`` (Gymnasium's ``np_random``), or a legacy
    ``RandomState`` for a spec that follows dm_control (``physics.convention``), whose
    tasks draw from one: ``uniform`` and ``normal`` are then ``RandomState``'s own calls.
    """

    __slots__ = ("generator",)

    def __init__(self, generator: Any = None):
        self.generator = generator

    def uniform(self, low: float, high: float) -> float:
        return float(self.generator.uniform(low, high))

    def normal(self, mean: float, std: float) -> float:
        return float(self.generator.normal(mean, std))

    def randint(self, low: float, high: float) -> float:
        if isinstance(self.generator, np.random.RandomState):
            return float(self.generator.randint(int(low), int(high) + 1))
        return float(self.generator.integers(int(low), int(high), endpoint=True))

    def uniform_disk(self, radius: float) -> tuple[float, float]:
        # the draws of Gymnasium's Reacher-v5 goal, exactly: uniform(-r, r, size=2) until its norm is below r
        while True:
            point = self.generator.uniform(low=-radius, high=radius, size=2)
            if radius <= 0 or float(np.linalg.norm(point)) < radius:
                return float(point[0]), float(point[1])

    def random_quaternion(self) -> tuple[float, ...]:
        # randomize_limited_and_rotational_joints' ball joint, exactly: randn(4), then divided by its norm
        legacy = isinstance(self.generator, np.random.RandomState)
        return _unit(self.generator.randn(4) if legacy else self.generator.standard_normal(4))

    def random_quaternion_positive(self) -> tuple[float, ...]:
        # its free joint, exactly: rand(4) (its comment: "this should be random.randn"), divided by its norm
        legacy = isinstance(self.generator, np.random.RandomState)
        return _unit(self.generator.rand(4) if legacy else self.generator.random(4))

    def choice(self, *values: Any) -> float:
        options = values[0] if len(values) == 1 and isinstance(values[0], tuple) else values
        draw = self.generator.randint if isinstance(self.generator, np.random.RandomState) else self.generator.integers
        return float(options[int(draw(len(options)))])


def bind_random(source: RandomSource) -> dict[str, Callable[..., Any]]:
    """The implementations of the random functions, drawing from `source`."""
    return {
        "uniform": source.uniform,
        "normal": source.normal,
        "randint": source.randint,
        "choice": source.choice,
        "uniform_disk": source.uniform_disk,
        "random_quaternion": source.random_quaternion,
        "random_quaternion_positive": source.random_quaternion_positive,
    }


def _unit(q: np.ndarray) -> tuple[float, ...]:
    """`q` divided by its length as numpy computes it (``q /= np.linalg.norm(q)``, dm_control's own lines)."""
    q /= np.linalg.norm(q)
    return tuple(float(v) for v in q)
