"""The generated code's LineMap: a traceback or a frame's line number back to the spec site.

Only the code generator numbers generated lines; everything that locates a
runtime fault asks its LineMap. These tests build small functions the way the
compiler does and check that each fault is traced to the statement that raised
it, not to a neighbour, the ``def`` line or a frame outside the generated code.
"""

from __future__ import annotations

import ast
import sys

import pytest

from visualenv import load_spec_text
from visualenv.compiler.program import compile_spec
from visualenv.expr.codegen import FunctionBuilder, LineMap, Site, const, function_globals, local, name

FIRST = Site("dynamics.let.a", "1 / x", ("x",))
SECOND = Site("reward", "1 / y", ("y",))


def divide(numerator: str, denominator: str) -> ast.expr:
    return ast.BinOp(name(local(numerator)), ast.Div(), name(local(denominator)))


def two_sites() -> FunctionBuilder:
    """f(x, y): an unsited statement, then 1 / x at FIRST and 1 / y at SECOND."""
    fb = FunctionBuilder("f", [local("x"), local("y")])
    fb.assign(local("one"), const(1.0))  # no site: shares the def line
    fb.assign("_a", divide("one", "x"), FIRST)
    fb.assign("_r", divide("one", "y"), SECOND)
    fb.returns(name("_r"))
    return fb


def fault_site(fb: FunctionBuilder, *args: float) -> Site | None:
    fn = fb.build(function_globals())
    with pytest.raises(ZeroDivisionError) as info:
        fn(*args)
    return fb.line_map().site_in(info.value.__traceback__)


def test_a_fault_is_traced_to_the_statement_that_raised_it():
    assert fault_site(two_sites(), 0.0, 1.0) is FIRST
    assert fault_site(two_sites(), 1.0, 0.0) is SECOND


def test_a_frame_line_number_maps_to_its_site_and_no_other_line_does():
    fb = two_sites()
    fn = fb.build(function_globals())
    lines = fb.line_map()
    seen = []

    def trace(frame, event, arg):  # records the line of every statement the generated frame runs
        if frame.f_code.co_filename == lines.filename and event == "line":
            seen.append(lines.site_at(frame.f_lineno))
        return trace

    sys.settrace(trace)
    try:
        fn(1.0, 1.0)
    finally:
        sys.settrace(None)
    assert seen == [None, FIRST, SECOND, None], "unsited statements share the def line, which maps to no site"
    assert lines.site_at(0) is None and lines.site_at(99) is None


def test_a_fault_outside_the_generated_code_has_no_site():
    def raise_elsewhere() -> None:
        raise ZeroDivisionError

    with pytest.raises(ZeroDivisionError) as info:
        raise_elsewhere()
    assert two_sites().line_map().site_in(info.value.__traceback__) is None
    assert two_sites().line_map().site_in(None) is None


def test_a_fault_inside_a_called_function_is_traced_to_the_calling_statement():
    def fails(value: float) -> float:
        raise ValueError("math domain error")

    fb = FunctionBuilder("g", [local("x")])
    fb.assign("_r", ast.Call(name("_f_fails"), [name(local("x"))], []), FIRST)
    fb.returns(name("_r"))
    fn = fb.build({**function_globals(), "_f_fails": fails})
    with pytest.raises(ValueError) as info:
        fn(1.0)
    assert fb.line_map().site_in(info.value.__traceback__) is FIRST


def test_find_names_the_first_site_of_a_spec_field():
    lines = LineMap("<visualenv:f>", (FIRST, SECOND, Site("reward", "again")))
    assert lines.find("reward") is SECOND
    assert lines.find("dynamics.update.x") is None


def test_a_compiled_program_has_a_line_map_per_generated_function():
    program = compile_spec(
        load_spec_text(
            "id: M-v0\nstate:\n  x: {init: 1}\nactions: {discrete: [{u: 1}]}\n"
            "dynamics: {update: {x: x + u}}\nreward: x * 2\n",
            "m.yaml",
        )
    )
    assert set(program.line_maps) == {"init", "step", "bind"}
    assert program.line_maps["init"].find("state.x.init").text == "1"
    assert program.line_maps["step"].find("dynamics.update.x").text == "x + u"
    assert program.line_maps["step"].find("reward").text == "x * 2"
    assert program.line_maps["bind"].sites == ()


def test_builds_share_one_compiled_body_each_in_its_own_globals():
    """A batch builds a set of functions per env: compiled once, each bound to its own env's names."""
    fb = FunctionBuilder("g", [local("x")])
    fb.assign("_r", ast.BinOp(name(local("x")), ast.Mult(), name("_scale")), FIRST)
    fb.returns(name("_r"))
    twice, thrice = (fb.build({**function_globals(), "_scale": k}) for k in (2.0, 3.0))
    assert twice.__code__ is thrice.__code__
    assert (twice(1.0), thrice(1.0)) == (2.0, 3.0)
    del fb.body[-1]  # the compiler edits bodies directly (physics_reset wraps statements in loops): compiled again
    fb.returns(const(0.0))
    assert fb.build({**function_globals(), "_scale": 2.0})(1.0) == 0.0
