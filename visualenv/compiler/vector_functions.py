"""The language's functions on numpy columns, giving what Python's give one env, to the bit, on any CPU.

A batch must compute what each env alone computes (:mod:`visualenv.compiler.vectorized`).
Three things stand in the way, and each is handled here:

* numpy's loops for ``tan``, ``exp``, ``atan2``... are its own SIMD code where the CPU has
  it (the AVX-512 SVML loops of numpy 1.x), not the C library that Python's ``math``
  calls: a third of their results differ in the last bit. Each such function is checked
  once against Python's on a fixed sample; where numpy's differs, the batch calls
  Python's for each element (slower, exact), else it keeps numpy's (the same C library);
* Python raises where numpy returns a number (``math.log(0)``, ``floor(inf)``): numpy's
  floating-point errors and these cases are noted while :func:`float_errors` watches, and
  the batch then steps its envs one by one, each raising its own located fault;
* a few definitions differ (``clip`` with low above high; NaN in ``min``): written as Python's.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import math
from typing import Any, Callable, Iterator

import numpy as np

from visualenv.expr.codegen import power
from visualenv.expr.functions import FUNCTIONS

#: the list of errors the innermost :func:`float_errors` is noting (None outside one)
_NOTING: contextvars.ContextVar[list[str] | None] = contextvars.ContextVar("visualenv_float_errors", default=None)


@contextlib.contextmanager
def float_errors() -> Iterator[list[str]]:
    """While inside, numpy warns of nothing and the list names each floating-point error met (division by
    zero, overflow, invalid operation; not underflow, which Python floats ignore too) and each value Python
    would have raised on: empty if there was none."""
    met: list[str] = []
    token = _NOTING.set(met)
    try:
        with np.errstate(all="call", under="ignore", call=lambda kind, flag: met.append(kind)):
            yield met
    finally:
        _NOTING.reset(token)


def _python_raised(name: str) -> None:
    met = _NOTING.get()
    if met is not None:
        met.append(name)


def _elementwise(name: str, scalar: Callable[..., float], arities: tuple[int, ...]) -> Callable[..., Any]:
    """Python's `scalar` on each element (NaN, and noted, where it raises: then element by element again, each caught)."""

    def safe(*args: float) -> float:
        try:
            return scalar(*args)
        except (ArithmeticError, ValueError):
            _python_raised(name)
            return math.nan

    ufuncs = {n: np.frompyfunc(scalar, n, 1) for n in arities}
    caught = {n: np.frompyfunc(safe, n, 1) for n in arities}

    def call(*args: Any) -> Any:
        try:
            return np.asarray(ufuncs[len(args)](*args), dtype=np.float64)
        except (ArithmeticError, ValueError):
            return np.asarray(caught[len(args)](*args), dtype=np.float64)

    call.__name__ = name
    return call


def _integral(name: str, ufunc: Callable[[Any], Any]) -> Callable[[Any], Any]:
    """floor, ceil, round: Python raises on an infinity or NaN, numpy returns it (noted)."""

    def call(x: Any) -> Any:
        out = ufunc(x)
        if not np.isfinite(out).all():
            _python_raised(name)
        return out

    return call


def _clip(x: Any, low: Any, high: Any) -> Any:
    """Python's definition (low if below, else high if above, else x), which np.clip's differs from when low > high."""
    if np.ndim(low) == 0 and np.ndim(high) == 0 and low <= high:
        return np.clip(x, low, high)  # the same values, faster
    return np.where(x < low, low, np.where(x > high, high, x))


def _reduce(op: Callable[[Any, Any], Any]) -> Callable[..., Any]:
    def call(*args: Any) -> Any:
        items = args[0] if len(args) == 1 and isinstance(args[0], tuple) else args
        return np.asarray(functools.reduce(op, items), dtype=np.float64)
    return call


def _log(x: Any, base: Any = None) -> Any:
    return np.log(x) if base is None else np.log(x) / np.log(base)


#: numpy's version of each deterministic function; those in _CHECKED are replaced where they differ from Python's
_NUMPY: dict[str, Callable[..., Any]] = {
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "asin": np.arcsin, "acos": np.arccos, "atan": np.arctan,
    "atan2": np.arctan2, "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh, "sqrt": np.sqrt, "exp": np.exp,
    "log": _log, "abs": np.abs, "min": _reduce(np.minimum), "max": _reduce(np.maximum), "clip": _clip,
    "hypot": _elementwise("hypot", math.hypot, (2, 3)),  # numpy's (C's hypot) differs from Python's own algorithm
    "floor": _integral("floor", np.floor), "ceil": _integral("ceil", np.ceil), "round": _integral("round", np.round),
    "sign": np.sign, "radians": np.radians, "degrees": np.degrees,
}
#: the functions numpy may compute with its own loops, and the inputs they are compared on (low, high)
_CHECKED: dict[str, tuple[float, float]] = {
    "sin": (-20, 20), "cos": (-20, 20), "tan": (-3, 3), "asin": (-1, 1), "acos": (-1, 1), "atan": (-50, 50), "atan2": (-5, 5),
    "sinh": (-20, 20), "cosh": (-20, 20), "tanh": (-5, 5), "exp": (-50, 50), "log": (1e-6, 1e6), "pow": (0.01, 10),
}
SAMPLE_SIZE = 1024


def _differs(name: str, fast: Callable[..., Any], exact: Callable[..., float]) -> bool:
    """Whether numpy's `fast` gives another value than Python's `exact` on a fixed sample of the function's inputs."""
    low, high = _CHECKED[name]
    rng = np.random.default_rng(len(name))
    args = [rng.uniform(low, high, SAMPLE_SIZE)] + ([rng.uniform(-3, 3, SAMPLE_SIZE)] if name in ("atan2", "pow") else [])
    with np.errstate(all="ignore"):
        ours = np.asarray(fast(*args), dtype=np.float64)
    return ours.tolist() != [exact(*values) for values in zip(*(a.tolist() for a in args))]


@functools.cache
def vector_functions() -> dict[str, Callable[..., Any]]:
    """The table a vectorised function calls (by the language's names, ``"pow"`` for ``**``): numpy's, or Python's
    element by element where numpy's differs on this machine (checked once per process)."""
    table = dict(_NUMPY)
    table["pow"] = np.float_power
    for name in _CHECKED:
        exact = power if name == "pow" else FUNCTIONS[name].impl
        assert exact is not None
        if _differs(name, table[name], exact):
            arities = (2,) if name in ("atan2", "pow") else ((1, 2) if name == "log" else (1,))
            table[name] = _elementwise(name, exact, arities)
    return table
