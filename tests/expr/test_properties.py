"""Property tests of the expression language (hypothesis).

* ``check()`` either returns or raises ExpressionError, for random expression
  trees built from the grammar, random text and random bytes: never another
  exception (no RecursionError, OverflowError, TypeError, ...).
* An expression that checks compiles, as the compiler compiles it, into code
  that returns a float, a bool or a tuple of floats, as its static type says,
  or raises only the documented runtime faults: ZeroDivisionError,
  OverflowError or ValueError.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from visualenv.errors import ExpressionError
from visualenv.expr import BOOL, FUNCTIONS, NUM, RandomSource, check, vec
from visualenv.expr.codegen import FunctionBuilder, Site, function_globals, local, lower, name
from visualenv.expr.functions import bind_random

NAMES = {"x": NUM, "y": NUM, "z": NUM, "flag": BOOL, "pos": vec(3)}
NUM_NAMES = ["x", "y", "z"]
RUNTIME_FAULTS = (ZeroDivisionError, OverflowError, ValueError)
FAST = settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much]
)

# -- the grammar ---------------------------------------------------------------------------------------

numbers = st.one_of(
    st.integers(-1000, 1000).map(str),
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
    st.sampled_from(["0", "0.0", "1", "0.5", "1e308", "1e-320", "2", "10", "pi", "e", "inf"]),
)
BINOPS = ["+", "-", "*", "/", "**", "%", "//"]
CMPOPS = ["<", "<=", ">", ">=", "==", "!="]


def _call(children: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    def one(fname: str) -> st.SearchStrategy[str]:
        f = FUNCTIONS[fname]
        hi = f.max_args if f.max_args is not None else f.min_args + 3
        return st.lists(children, min_size=max(0, f.min_args - 1), max_size=hi + 1).map(
            lambda args: f"{fname}({', '.join(args)})"
        )

    return st.sampled_from(sorted(FUNCTIONS)).flatmap(one)


def _any_tree(children: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    return st.one_of(
        st.tuples(children, st.sampled_from(BINOPS), children).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        st.tuples(children, st.sampled_from(CMPOPS), children).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        st.tuples(children, st.sampled_from(CMPOPS), children, st.sampled_from(CMPOPS), children).map(
            lambda t: f"({' '.join(t)})"
        ),
        st.tuples(children, st.sampled_from(["and", "or"]), children).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        children.map(lambda c: f"(not {c})"),
        children.map(lambda c: f"(-{c})"),
        st.tuples(children, children, children).map(lambda t: f"({t[0]} if {t[1]} else {t[2]})"),
        _call(children),
        st.lists(children, min_size=1, max_size=4).map(lambda items: "[" + ", ".join(items) + "]"),
    )


#: untyped trees: mostly type errors, which is the point
any_expr = st.recursive(
    st.one_of(numbers, st.sampled_from([*NAMES, "True", "False", "nope", "sin"])), _any_tree, max_leaves=30
)


# typed trees: numbers, conditions and 3-vectors that usually check, so they can run
def _num_tree(num: st.SearchStrategy[str], cond: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
    def typed_call(fname: str) -> st.SearchStrategy[str]:
        f = FUNCTIONS[fname]
        lo = 2 if fname == "choice" else f.min_args
        hi = f.max_args if f.max_args is not None else lo + 3
        return st.lists(num, min_size=lo, max_size=hi).map(lambda args: f"{fname}({', '.join(args)})")

    binop = st.tuples(num, st.sampled_from(BINOPS), num).map(lambda t: f"({t[0]} {t[1]} {t[2]})")
    return st.one_of(
        binop,
        binop,
        num.map(lambda c: f"(-{c})"),
        st.tuples(num, cond, num).map(lambda t: f"({t[0]} if {t[1]} else {t[2]})"),
        st.sampled_from(sorted(FUNCTIONS)).flatmap(typed_call),
        st.just("choice(pos)"),
    )


num_expr = st.deferred(lambda: st.one_of(st.sampled_from(NUM_NAMES), numbers, _num_tree(num_expr, cond_expr)))
cond_expr = st.deferred(
    lambda: st.one_of(
        st.sampled_from(["True", "False", "flag"]),
        st.tuples(num_expr, st.sampled_from(CMPOPS), num_expr).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        st.tuples(cond_expr, st.sampled_from(["and", "or"]), cond_expr).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        cond_expr.map(lambda c: f"(not {c})"),
    )
)
vec_expr = st.one_of(
    st.lists(num_expr, min_size=3, max_size=3).map(lambda items: "[" + ", ".join(items) + "]"),
    st.just("pos"),
    st.tuples(st.lists(num_expr, min_size=3, max_size=3), cond_expr).map(
        lambda t: f"([{', '.join(t[0])}] if {t[1]} else pos)"
    ),
)
typed_expr = st.one_of(num_expr, num_expr, cond_expr, vec_expr)

values = st.one_of(
    st.floats(-10, 10),
    st.sampled_from([0.0, -0.0, 1.0, -1.0, 0.5, -2.5, 1e308, -1e308, math.inf, -math.inf, math.nan]),
    st.floats(allow_nan=True, allow_infinity=True, width=64),
)

# -- helpers --------------------------------------------------------------------------------------------------


def _check_or_expression_error(text: object):
    try:
        return check(text, NAMES)  # type: ignore[arg-type]
    except ExpressionError as exc:
        assert isinstance(exc.message, str) and exc.message
        assert isinstance(exc.offset, int) and exc.offset >= 0
        return None


def _compile(checked) -> object:
    """Compile a checked tree the way the compiler does (a FunctionBuilder over lowered trees)."""
    fb = FunctionBuilder("f", [local(n) for n in NAMES])
    fb.assign("_r", lower(checked.tree), Site("expr", checked.text, tuple(sorted(checked.names))))
    fb.returns(name("_r"))
    rng = np.random.default_rng(0)
    return fb.build(function_globals(bind_random(RandomSource(rng))))


def _run(checked, x: float, y: float, z: float, flag: bool, pos: tuple[float, float, float]) -> None:
    fn = _compile(checked)
    try:
        result = fn(x, y, z, flag, pos)
    except RUNTIME_FAULTS:
        return
    if checked.type == NUM:
        assert type(result) is float, (checked.text, result)
    elif checked.type == BOOL:
        assert type(result) is bool, (checked.text, result)
    else:
        assert checked.type.kind == "vec"
        assert type(result) is tuple and len(result) == checked.type.size, (checked.text, result)
        assert all(type(v) is float for v in result), (checked.text, result)
    if checked.constant is not None:  # folding agrees with running
        same = result == checked.constant or (
            isinstance(result, float) and math.isnan(result) and math.isnan(checked.constant)
        )
        assert same or checked.random, (checked.text, result, checked.constant)


# -- properties ---------------------------------------------------------------------------------------------


@FAST
@given(any_expr)
def test_check_only_raises_expression_error_on_grammar_trees(text: str):
    _check_or_expression_error(text)


@FAST
@given(st.text(max_size=200))
def test_check_only_raises_expression_error_on_random_text(text: str):
    _check_or_expression_error(text)


@FAST
@given(st.text(alphabet="xyzpos flag0123456789.+-*/%()[],<>=!andotifelsqrcmupw_eE:'\"{}@~^&|\\\n\t", max_size=80))
def test_check_only_raises_expression_error_on_near_miss_text(text: str):
    _check_or_expression_error(text)


@FAST
@given(st.binary(max_size=200))
def test_check_only_raises_expression_error_on_random_bytes(data: bytes):
    _check_or_expression_error(data)
    _check_or_expression_error(data.decode("utf-8", errors="surrogateescape"))
    _check_or_expression_error(data.decode("latin-1"))


@FAST
@given(st.one_of(st.integers(), st.floats(), st.booleans(), st.none(), st.lists(st.integers(), max_size=3)))
def test_check_only_raises_expression_error_on_plain_values(value: object):
    _check_or_expression_error(value)


@settings(FAST, max_examples=60)
@given(any_expr, values, values, values, st.booleans(), st.tuples(values, values, values))
def test_untyped_trees_that_check_run_safely(text: str, x: float, y: float, z: float, flag: bool, pos: tuple):
    checked = _check_or_expression_error(text)
    assume(checked is not None)
    _run(checked, x, y, z, flag, pos)


@FAST
@given(typed_expr, values, values, values, st.booleans(), st.tuples(values, values, values))
# regressions: a negative number to a fractional power was a complex number, not a domain error
@example("(x ** y)", -2.0, 0.5, 0.0, False, (0.0, 0.0, 0.0))
@example("sin((x ** z))", -8.0, 0.0, 1 / 3, True, (0.0, 0.0, 0.0))
@example("((-8) ** (1 / 3))", 0.0, 0.0, 0.0, True, (0.0, 0.0, 0.0))
@example("(inf - inf)", 0.0, 0.0, 0.0, True, (0.0, 0.0, 0.0))
@example("randint(x, y)", 5.0, 1.0, 0.0, True, (0.0, 0.0, 0.0))
@example("normal(x, y)", 0.0, -1.0, 0.0, True, (0.0, 0.0, 0.0))
@example("floor(x)", math.nan, 0.0, 0.0, True, (0.0, 0.0, 0.0))
@example("choice(pos)", 0.0, 0.0, 0.0, True, (1.0, 2.0, 3.0))
def test_typed_trees_check_and_run_to_their_type_or_a_documented_fault(
    text: str, x: float, y: float, z: float, flag: bool, pos: tuple
):
    checked = _check_or_expression_error(text)
    assume(checked is not None)
    _run(checked, x, y, z, flag, pos)


def test_typed_grammar_mostly_checks():
    """Guard the generator: most typed trees must pass the checker, or the run properties test little."""
    ok = 0
    total = 0

    @settings(max_examples=100, deadline=None, database=None)
    @given(typed_expr)
    def count(text: str) -> None:
        nonlocal ok, total
        total += 1
        ok += _check_or_expression_error(text) is not None

    count()
    assert ok >= total // 4, (ok, total)


# -- long flat chains and constant arguments (issue 18) ------------------------------------------------------


@FAST
@given(
    st.lists(
        st.tuples(st.sampled_from(["+", "-", "*"]), st.sampled_from(["x", "y", "1", "2.5"])), min_size=1, max_size=140
    ),
    values,
    values,
)
def test_flat_chains_are_not_nesting_and_run_like_python(chain: list, x: float, y: float):
    """`a + b - c * ...` of up to 140 operations checks (a flat sum is not "deeply nested") and computes what Python computes."""
    text = "x" + "".join(f" {op} {term}" for op, term in chain)
    checked = check(text, NAMES)
    fn = _compile(checked)
    with np.errstate(all="ignore"):
        try:
            expected = float(eval(text, {}, {"x": x, "y": y}))  # noqa: S307 - the test's own text of + - * and numbers
        except OverflowError:
            return
    try:
        result = fn(x, y, 0.0, False, (0.0, 0.0, 0.0))
    except OverflowError:
        return
    assert result == expected or (math.isnan(result) and math.isnan(expected))


def test_a_chain_longer_than_the_limit_says_so_not_nesting():
    with pytest.raises(ExpressionError) as caught:
        check(" + ".join(["x"] * 200), NAMES)
    assert "chained" in caught.value.message and "nested" not in caught.value.message


@FAST
@given(st.integers(-50, 50), st.integers(-50, 50), st.sampled_from(["uniform", "randint", "clip"]))
def test_bounds_in_the_wrong_order_fail_at_check(low: int, high: int, fname: str):
    text = f"clip(x, {low}, {high})" if fname == "clip" else f"{fname}({low}, {high})"
    if low <= high:
        check(text, NAMES)
    else:
        with pytest.raises(ExpressionError) as caught:
            check(text, NAMES)
        assert "needs low <= high" in caught.value.message


@FAST
@given(st.floats(-1e6, 1e6, allow_nan=False))
def test_a_negative_constant_std_fails_at_check(std: float):
    if std >= 0:
        check(f"normal(0, {std!r})", NAMES)
    else:
        with pytest.raises(ExpressionError) as caught:
            check(f"normal(0, {std!r})", NAMES)
        assert "std >= 0" in caught.value.message
