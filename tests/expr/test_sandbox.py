"""Escape attempts from the history of Python expression sandboxes: all rejected at build time.

Each attempt is rejected by :func:`visualenv.expr.check` and again inside a spec
by :func:`visualenv.compile_spec`, with a message that says what is not
allowed, quickly, and without running anything: the attempts that would write a
file or set a global leave no trace. The code generated from valid specs runs
with empty builtins and sees only the function table.
"""

from __future__ import annotations

import builtins
import json
import types
from pathlib import Path

import pytest

from visualenv import SpecError, compile_spec, load_spec_text
from visualenv.errors import ExpressionError
from visualenv.expr import NUM, FUNCTIONS, RandomSource, check
from visualenv.expr.codegen import FUNC_PREFIX, POW, VAR_PREFIX, evaluate_constant, function_globals

NAMES = {"x": NUM, "v": NUM}
SENTINEL = "VISUALENV_SANDBOX_PWNED"
MARKER = "{marker}"  # replaced by a file path in tmp_path

CALL = "only the built-in functions can be called"
ATTR = "attribute access ('.') not allowed"
SUBSCRIPT = "subscripts ('[...]' after a value) not allowed"

#: (attempt, a fragment of the message it must be rejected with)
ATTEMPTS: list[tuple[str, str]] = [
    # dunder chains to object.__subclasses__ and from there to os/subprocess
    ("().__class__.__bases__[0].__subclasses__()", CALL),
    ("[].__class__.__base__.__subclasses__()", CALL),
    ("x.__class__.__mro__", ATTR),
    ("True.__class__", ATTR),
    ("sin.__globals__", ATTR),
    ("(lambda: 0).__code__", ATTR),
    ("x.__reduce__()", CALL),
    ("x.__reduce_ex__(2)", CALL),
    # imports and builtins
    (f"__import__('os').system('touch {MARKER}')", CALL),
    (f"__import__('pathlib').Path('{MARKER}').touch()", CALL),
    ("__import__('builtins').__dict__.update(" + SENTINEL + "=1)", CALL),
    ("__import__", "unknown name '__import__'"),
    ("__builtins__", "unknown name '__builtins__'"),
    ("__builtins__['eval']", SUBSCRIPT),
    ("__loader__", "unknown name '__loader__'"),
    ("getattr(x, '__class__')", "unknown function 'getattr'"),
    ("setattr(x, 'real', 1)", "unknown function 'setattr'"),
    ("globals()", "unknown function 'globals'"),
    ("locals()", "unknown function 'locals'"),
    ("vars()", "unknown function 'vars'"),
    ("dir()", "unknown function 'dir'"),
    ("eval('1 + 1')", "unknown function 'eval'"),
    (f"exec('import builtins; builtins.{SENTINEL} = 1')", "unknown function 'exec'"),
    ("compile('1', '<s>', 'eval')", "unknown function 'compile'"),
    (f"open('{MARKER}', 'w')", "unknown function 'open'"),
    ("breakpoint()", "unknown function 'breakpoint'"),
    ("type(1)", "unknown function 'type'"),
    ("\uff45\uff56\uff41\uff4c('1')", "unknown function 'eval'"),  # fullwidth 'eval' is NFKC-normalised to eval
    # generated-code internals are not reachable by name
    ("_f_sin(1)", "unknown function '_f_sin'"),
    ("_v_x", "unknown name '_v_x'"),
    (f"{POW}(2, 3)", f"unknown function '{POW}'"),
    ("_random", "unknown name '_random'"),
    # frames, format strings, pickling hooks
    ("(y for y in ()).gi_frame.f_globals", ATTR),
    ("'{0.__class__}'.format(1)", CALL),
    ("'%s' % x", "text values are not allowed"),
    ("f'{x}'", "f-strings not allowed"),
    ("f'{x.__class__}'", "f-strings not allowed"),
    # syntax outside the language
    ("lambda: 1", "lambda not allowed"),
    ("[y for y in [1, 2]]", "comprehensions not allowed"),
    ("{y: 1 for y in [1]}", "comprehensions not allowed"),
    ("min((y for y in [1]), 2)", "generator expressions not allowed"),
    ("(y := 1)", "assignment expressions (':=') not allowed"),
    ("max(*[1, 2])", "'*' unpacking not allowed"),
    ("max(x, *[1, 2])", "'*' unpacking not allowed"),
    ("round(x, ndigits=2)", "takes no keyword arguments"),
    ("max(x, **{'a': 1})", "takes no keyword arguments"),
    ("(1).real", ATTR),
    ("x.real", ATTR),
    ("x[0]", SUBSCRIPT),
    ("[1, 2][0]", SUBSCRIPT),
    ("[1, 2][0:1]", SUBSCRIPT),
    ("sin(x)(1)", CALL),
    ("x if x > 0 else __import__('os')", "unknown function '__import__'"),
    ("x; import os", "syntax error"),
    ("import os", "syntax error"),
    ("yield x", "syntax error"),
    ("await x", "await not allowed"),
    ("x is None", "only <, <=, >, >=, == and != comparisons are allowed"),
    ("x in [1]", "only <, <=, >, >=, == and != comparisons are allowed"),
    ("(1, 2)", "tuples"),
    ("{1, 2}", "sets not allowed"),
    ("{'a': 1}", "dicts not allowed"),
    ("b'x'", "bytes values are not allowed"),
    ("'a' * 10**9", "text values are not allowed"),
    ("[0] * 10**9", "'*' needs a number, got a vector of 1"),
    ("x << 1", "bitwise"),
    ("~x", "bitwise"),
    ("x @ v", "matrix"),
    # resource exhaustion
    ("x + " * 3000 + "x", "expression is too long"),
    ("9**9**9", "numeric overflow"),
    ("10**10**10", "numeric overflow"),
    ("2.0 ** 10000", "numeric overflow"),
    ("exp(1000)", "numeric overflow"),
    ("(" * 10000 + "x" + ")" * 10000, "expression is too long"),
    ("(" * 1300 + "x" + ")" * 1300, "too many nested parentheses"),
    ("(1 + " * 100 + "x" + ")" * 100, "too deeply nested"),  # nested to the right: (((x + 1) + 1) ...) is a flat sum
    ("(" * 200 + "x" + " + 1)" * 200, "chained"),
    ("-" * 3000 + "x", "too deeply nested"),
    ("sin(" * 100 + "x" + ")" * 100, "too deeply nested"),
    ("1e999", "number is too large"),
    ("1" + "0" * 5000, "expression is too long"),
    ("1" + "0" * 3990, "number is too large"),
    ("max(" + ", ".join(["x*x"] * 700) + ")", "expression is too large"),
    ("inf - inf", "not a number (NaN)"),
    ("(-8) ** 0.5", "a negative number to a fractional power"),
]


@pytest.fixture
def marker(tmp_path: Path) -> Path:
    return tmp_path / "pwned.txt"


def _text(attempt: str, marker: Path) -> str:
    return attempt.replace(MARKER, str(marker))


def _assert_no_trace(marker: Path) -> None:
    assert not marker.exists(), "an attempt wrote a file"
    assert not hasattr(builtins, SENTINEL), "an attempt set a builtin"
    assert SENTINEL not in globals(), "an attempt set a global"


@pytest.mark.timeout(
    20
)  # a bound, not a figure: an attempt that makes the checker hang (a huge power, deep nesting) fails here
@pytest.mark.parametrize("attempt, fragment", ATTEMPTS, ids=[a[:40] for a, _ in ATTEMPTS])
def test_check_rejects_attempt(attempt: str, fragment: str, marker: Path):
    with pytest.raises(ExpressionError) as err:
        check(_text(attempt, marker), NAMES)
    assert fragment in err.value.message
    _assert_no_trace(marker)


@pytest.mark.parametrize("attempt, fragment", ATTEMPTS, ids=[a[:40] for a, _ in ATTEMPTS])
def test_compile_spec_rejects_attempt_in_every_place(attempt: str, fragment: str, marker: Path):
    """The same attempt as a reward, an update, a let, an init, an outcome and an actor binding."""
    text = _text(attempt, marker)
    spec = {
        "id": "Sandbox-v0",
        "scene": {"objects": {"Box": {"primitive": "cube"}}},
        "state": {"x": {"init": 0}, "v": {"init": text}},
        "actions": {"discrete": [{"u": -1}, {"u": 1}]},
        "dynamics": {"let": {"a": text}, "update": {"x": text}},
        "actors": {"Box": {"location": [text, 0, 0]}},
        "reward": text,
        "outcomes": {"done": {"when": text}},
    }
    # JSON is YAML: the attempt's quotes and backslashes survive without escaping by hand
    loaded = load_spec_text(json.dumps(spec, indent=1), "sandbox.yaml")
    with pytest.raises(SpecError) as err:
        compile_spec(loaded)
    lines = str(err.value).splitlines()
    places = (
        "state.v.init",
        "dynamics.let.a",
        "dynamics.update.x",
        "actors.Box.location[0]",
        "reward",
        "outcomes.done.when",
    )
    for place in places:
        line = next((row for row in lines if f" {place}: " in row), None)
        assert line is not None, f"no problem reported at {place}:\n{err.value}"
        assert line.startswith("sandbox.yaml:"), line
        assert fragment in line, line
    _assert_no_trace(marker)


def test_plain_parentheses_are_harmless():
    """Redundant parentheses make no nesting: accepted, and just the name."""
    checked = check("(" * 100 + "x" + ")" * 100, NAMES)
    assert checked.names == {"x"} and checked.type == NUM


def test_yaml_python_tags_are_never_constructed(marker: Path):
    text = f'id: S-v0\nstate:\n  x: {{init: !!python/object/apply:os.system ["touch {marker}"]}}\nactions: {{discrete: [{{u: 1}}]}}\n'
    with pytest.raises(SpecError, match="YAML tags such as '!!python/object/apply:os.system' are not allowed"):
        load_spec_text(text, "tag.yaml")
    _assert_no_trace(marker)


VALID = """
id: Valid-v0
params: {k: 2}
scene:
  objects:
    Box: {primitive: cube}
state:
  x: {init: "uniform(-1, 1)"}
  v: {init: "choice(1, 2, 3)"}
actions:
  discrete:
    - {u: -1}
    - {u: 1}
dynamics:
  let:
    a: "x ** 2 + sin(v) * k"
  update:
    x: "clip(x + u * 0.1, -1, 1)"
    v: "v * 0.9 + normal(0, 0.01) if a < 10 else 0"
actors:
  Box: {location: "[x, 0, v]", visible: "x > 0"}
reward: "-abs(x) - a / 100"
outcomes:
  out: {when: "abs(x) >= 1"}
"""


def _code_objects(code: types.CodeType):
    yield code
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            yield from _code_objects(const)


def test_generated_code_has_no_builtins():
    program = compile_spec(load_spec_text(VALID, "valid.yaml"))
    fns = program.functions(RandomSource())
    allowed_globals = {"__builtins__", POW, "_python_dynamics", "_random"} | {FUNC_PREFIX + n for n in FUNCTIONS}
    for fn in (fns.init, fns.step, fns.bind):
        assert fn.__globals__["__builtins__"] == {}
        assert fn.__builtins__ == {}
        assert set(fn.__globals__) <= allowed_globals | {fn.__name__}, set(fn.__globals__) - allowed_globals
        for code in _code_objects(fn.__code__):
            for name in code.co_names:
                # every global the code reads is a table function or a generated helper
                assert name.startswith((FUNC_PREFIX, "_")) and name in allowed_globals | {"get", "generator"}, name
            for name in code.co_varnames:
                assert name.startswith((VAR_PREFIX, "_")), name
        # and those globals cannot reach the builtins either
        for probe in ("__import__", "open", "eval", "getattr"):
            with pytest.raises(NameError):
                eval(probe, fn.__globals__)  # noqa: S307 - probing the sandbox's globals
    assert function_globals()["__builtins__"] == {}


def test_constant_folding_runs_without_builtins():
    import ast

    with pytest.raises(NameError):
        evaluate_constant(
            ast.Call(ast.Name("open", ast.Load()), [], [])
        )  # not reachable from a spec: the checker refuses it
