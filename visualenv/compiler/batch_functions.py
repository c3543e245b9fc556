"""The language's functions on numpy columns, giving what Python's give one env, to the bit, on any CPU.

A batch must compute what each env alone computes (:mod:`visualenv.compiler.batch_step`).
Three things stand in the way, and each is handled here:

* numpy's loops for ``tan``, ``exp``, ``atan2``... are its own SIMD code where the CPU has
  it (the AVX-512 SVML loops of numpy 1.x), not the C library that Python's ``math``
  calls: a third of their results differ in the last bit. Each such function is checked
  once against Python's on a fixed sample; where numpy's differs, the batch calls
  Python's for each element (slower, exact), else it keeps numpy's (the same C library);
* Python raises where numpy returns a number (``1 / 0``, ``math.log(0)``, ``floor(inf)``):
  each operation Python can raise on records its output while :func:`float_errors`
  watches, and the record says which met a value Python raises on (a zero divisor; a
  math function's NaN from numbers or infinity from finite numbers, CPython's own rule;
  ``floor`` of an infinity...); the batch then steps its envs one by one, each raising
  its own located fault. numpy's floating-point error flags are not used: checking
  them after every ufunc call (``np.errstate(all="call")``) slows every step
  (results/benchmarks/code-choices.md), and they fire where Python raises nothing;
* a few definitions differ (``clip`` with low above high; NaN in ``min``, ``max`` and
  ``sign``, where Python's answer depends on the order): written as Python's, or noted.
"""

from __future__ import annotations

import ast
import contextvars
import functools
import math
from typing import Any, Callable

import numpy as np

from visualenv.expr.codegen import power
from visualenv.expr.functions import FUNCTIONS
from visualenv.expr.tolerance import tolerance_columns


class Noted:
    """What :func:`float_errors` collected: the operations that met a value Python raises on.

    Operations record their outputs as they run (Python raises only where numpy's output is
    not finite); the checks run together when the record is read (``bool(noted)``,
    :attr:`names`): in the common case, where every value is finite, one test of all the
    columns at once instead of one per operation.
    """

    __slots__ = ("_names", "_columns", "_outputs")

    def __init__(self) -> None:
        self._names: list[str] = []
        self._columns: list[np.ndarray] = []  # every output column, for the one finiteness test
        self._outputs: list[tuple[str, Callable[[Any, tuple], bool], tuple, Any]] = []

    def raised(self, name: str) -> None:
        """Python raised in operation `name` (an element-wise Python function)."""
        self._names.append(name)

    def output(self, name: str, rule: Callable[[Any, tuple], bool], args: tuple, out: Any) -> None:
        """`out` of operation `name` on `args`; if not all finite, `rule(out, args)` says whether Python raises."""
        if type(out) is np.ndarray and out.ndim == 1 and out.dtype.kind == "f":
            self._columns.append(out)
            self._outputs.append((name, rule, args, out))
        elif (not math.isfinite(out) if isinstance(out, float) else True) and rule(out, args):
            self._names.append(name)  # a number, or integers (5 // 0 is 0 in numpy, no NaN to find later): tested now

    @property
    def names(self) -> list[str]:
        """The operations that met a value Python raises on, in the order found."""
        if self._columns:
            if not np.isfinite(np.concatenate(self._columns)).all():
                self._names += [name for name, rule, args, out in self._outputs if rule(out, args)]
            self._columns, self._outputs = [], []
        return self._names

    def __bool__(self) -> bool:
        return bool(self.names)


#: the record of the innermost :func:`float_errors` (None outside one)
_NOTING: contextvars.ContextVar[Noted | None] = contextvars.ContextVar("visualenv_float_errors", default=None)


class float_errors:  # noqa: N801 - used as a function: with float_errors() as noted
    """While inside, numpy warns of nothing, and the record notes each operation of this table that met a value
    Python raises on (the batch's sign to step its envs one by one): false if there was none."""

    __slots__ = ("_token", "_numpy")

    def __enter__(self) -> Noted:
        noted = Noted()
        self._token = _NOTING.set(noted)
        self._numpy = np.seterr(all="ignore")
        return noted

    def __exit__(self, *exc: Any) -> None:
        np.seterr(**self._numpy)
        _NOTING.reset(self._token)


def _python_rule(out: Any, args: tuple) -> bool:
    """CPython's math raises where a result is NaN from numbers, or infinite from finite numbers."""
    nan_in = functools.reduce(np.logical_or, [np.isnan(a) for a in args])
    finite_in = functools.reduce(np.logical_and, [np.isfinite(a) for a in args])
    return bool((np.isnan(out) & ~nan_in).any() or (np.isinf(out) & finite_in).any())


def _not_finite(out: Any, args: tuple) -> bool:
    """floor, ceil, round: Python raises on an infinity or NaN, numpy returns it."""
    return not np.isfinite(out).all()


def _nan(out: Any, args: tuple) -> bool:
    """min, max, sign: where numpy gives NaN, Python's answer depends on the argument order (min(1, nan) is 1)."""
    return bool(np.isnan(out).any())


def _noting(name: str, function: Callable[..., Any], rule: Callable[[Any, tuple], bool]) -> Callable[..., Any]:
    """numpy's `function`, its output recorded for `rule` while :func:`float_errors` watches."""

    def call(*args: Any) -> Any:
        out = function(*args)
        noted = _NOTING.get()
        if noted is not None:
            noted.output(name, rule, args, out)
        return out

    return call


def _by_zero(out: Any, args: tuple) -> bool:
    """``/``, ``//``, ``%``: Python raises on a zero divisor (even 0 / 0), where numpy's result is not finite."""
    return not np.all(np.asarray(args[1]) != 0)


def _python_raised(name: str) -> None:
    noted = _NOTING.get()
    if noted is not None:
        noted.raised(name)


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
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "asin": np.arcsin,
    "acos": np.arccos,
    "atan": np.arctan,
    "atan2": np.arctan2,
    "sinh": np.sinh,
    "cosh": np.cosh,
    "tanh": np.tanh,
    "asinh": np.arcsinh,
    "sqrt": np.sqrt,
    "exp": np.exp,
    "log": _log,
    "log1p": np.log1p,
    "abs": np.abs,
    "min": _noting("min", _reduce(np.minimum), _nan),
    "max": _noting("max", _reduce(np.maximum), _nan),
    "clip": _clip,
    "hypot": _elementwise("hypot", math.hypot, (2, 3)),  # numpy's (C's hypot) differs from Python's own algorithm
    "floor": _noting("floor", np.floor, _not_finite),
    "ceil": _noting("ceil", np.ceil, _not_finite),
    "round": _noting("round", np.round, _not_finite),
    "sign": _noting("sign", np.sign, _nan),
    "radians": np.radians,
    "degrees": np.degrees,
    "tolerance": tolerance_columns,  # dm_control's, the scalar code per env (NaN where its arguments are refused: the lane raises)
}
#: the operators Python raises on, as the vectorised code calls them
OPERATORS: dict[type, Callable[[Any, Any], Any]] = {
    ast.Div: _noting("/", np.true_divide, _by_zero),
    ast.FloorDiv: _noting("//", np.floor_divide, _by_zero),
    ast.Mod: _noting("%", np.remainder, _by_zero),
}
#: the functions numpy may compute with its own loops, and the inputs they are compared on (low, high)
_CHECKED: dict[str, tuple[float, float]] = {
    "sin": (-20, 20),
    "cos": (-20, 20),
    "tan": (-3, 3),
    "asin": (-1, 1),
    "acos": (-1, 1),
    "atan": (-50, 50),
    "atan2": (-5, 5),
    "sinh": (-20, 20),
    "cosh": (-20, 20),
    "tanh": (-5, 5),
    "asinh": (-1e3, 1e3),
    "exp": (-50, 50),
    "log": (1e-6, 1e6),
    "log1p": (-0.999, 1e6),
    "pow": (0.01, 10),
}
SAMPLE_SIZE = 1024


def _differs(name: str, fast: Callable[..., Any], exact: Callable[..., float]) -> bool:
    """Whether numpy's `fast` gives another value than Python's `exact` on a fixed sample of the function's inputs."""
    low, high = _CHECKED[name]
    rng = np.random.default_rng(len(name))
    args = [rng.uniform(low, high, SAMPLE_SIZE)] + (
        [rng.uniform(-3, 3, SAMPLE_SIZE)] if name in ("atan2", "pow") else []
    )
    with np.errstate(all="ignore"):
        ours = np.asarray(fast(*args), dtype=np.float64)
    return ours.tolist() != [exact(*values) for values in zip(*(a.tolist() for a in args))]


@functools.cache
def vector_functions() -> dict[str, Callable[..., Any]]:
    """The table a vectorised function calls (by the language's names, ``"pow"`` for ``**``): numpy's, or Python's
    element by element where numpy's differs on this machine (checked once per process)."""
    table = dict(_NUMPY)
    table["pow"] = np.float_power
    for name in [*_CHECKED, "sqrt"]:
        exact = power if name == "pow" else FUNCTIONS[name].impl
        assert exact is not None
        if name != "sqrt" and _differs(name, table[name], exact):
            arities = (2,) if name in ("atan2", "pow") else ((1, 2) if name == "log" else (1,))
            table[name] = _elementwise(name, exact, arities)
        else:
            table[name] = _noting(name, table[name], _python_rule)
    return table
