"""Parse an expression and check it against the allow-list, node by node.

Text is parsed with :func:`ast.parse` in ``eval`` mode and every node is
checked: only numbers, names, arithmetic, comparisons, ``and``/``or``/``not``,
conditional expressions, vector literals and calls of the functions in
:data:`~visualenv.expr.functions.FUNCTIONS` are accepted. Names must be in the
table the caller passes (params, state, inputs, ``let`` names, built-ins).
Numbers become floats, so integer power towers cannot run for ever; constant
subexpressions are folded now, so ``9**9**9`` is an overflow error at build time.
The result is a new tree made only of allowed nodes, ready for code generation.
"""

from __future__ import annotations

import ast
import math
import warnings
from dataclasses import dataclass, field
from collections import ChainMap
from typing import Mapping, MutableMapping, cast

from visualenv.errors import ExpressionError, did_you_mean
from visualenv.expr.functions import CONSTANTS, FUNCTIONS, Function, Param
from visualenv.expr.tolerance import SIGMOIDS, problem as tolerance_problem
from visualenv.expr.types import BOOL, NUM, Type, vec

MAX_LENGTH = 4000
MAX_DEPTH = 40
#: deepest syntax tree (a flat sum of n terms is n deep): code generation recurses on the tree
MAX_TREE_DEPTH = 150
MAX_NODES = 2000
MAX_VECTOR = 64
MAX_LITERAL = 1e300

_BINOPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.FloorDiv: "//", ast.Mod: "%", ast.Pow: "**"}
_CMPOPS = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!="}
_DESCRIBE = {
    ast.Attribute: "attribute access ('.')",
    ast.Subscript: "subscripts ('[...]' after a value)",
    ast.Lambda: "lambda",
    ast.ListComp: "comprehensions",
    ast.SetComp: "comprehensions",
    ast.DictComp: "comprehensions",
    ast.GeneratorExp: "generator expressions",
    ast.JoinedStr: "f-strings",
    ast.FormattedValue: "f-strings",
    ast.NamedExpr: "assignment expressions (':=')",
    ast.Starred: "'*' unpacking",
    ast.Dict: "dicts",
    ast.Set: "sets",
    ast.Tuple: "tuples (use [a, b, c] for a vector)",
    ast.Await: "await",
    ast.Yield: "yield",
    ast.YieldFrom: "yield",
    ast.Slice: "slices",
}


@dataclass
class Checked:
    """A checked expression: a tree of allowed nodes, its type and what it reads."""

    text: str
    tree: ast.expr
    type: Type
    names: set[str] = field(default_factory=set)
    random: bool = False
    constant: float | bool | tuple | None = None  # set when the whole expression folded


def parse(text: str | float | int | bool) -> ast.expr:
    """Parse expression text (numbers and booleans are accepted as themselves).

    An error's offset is a character of `text` as given: a value written over several lines
    (a YAML block) is parsed with its line breaks as spaces, so that a place in it is a place in
    `text`, and the file's map of the value (:mod:`visualenv.spec.text_places`) names the line.
    """
    return _parse(text)[0]


def _parse(text: str | float | int | bool) -> tuple[ast.expr, str, int]:
    """The tree, the text it was parsed from (one line, stripped) and how many characters of `text` precede it."""
    if isinstance(text, bool):
        return ast.Constant(text), "", 0
    if isinstance(text, (int, float)):
        return ast.Constant(_number(text, 0)), "", 0
    if not isinstance(text, str):
        raise ExpressionError(f"expected a number or an expression, got {type(text).__name__}")
    if not text.strip():
        raise ExpressionError("empty expression")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"expression is too long ({len(text)} characters, at most {MAX_LENGTH})")
    flat = text.replace("\r", " ").replace("\n", " ")  # as long as the text: an offset in it is one in the text
    lead = len(flat) - len(flat.lstrip())
    parsed = flat.strip()
    try:
        with warnings.catch_warnings():  # e.g. "invalid escape sequence" in a text the checker rejects anyway
            warnings.simplefilter("ignore")
            module = ast.parse(parsed, mode="eval")
    except SyntaxError as exc:
        offset = lead + (exc.offset or 1) - 1
        raise ExpressionError(f"syntax error: {exc.msg}", offset) from None
    except UnicodeError:  # e.g. a lone surrogate: ast.parse cannot encode the text
        raise ExpressionError("the expression contains characters that are not valid text") from None
    except ValueError as exc:  # e.g. null bytes (Python 3.11 raises ValueError, later SyntaxError)
        raise ExpressionError(f"syntax error: {exc}") from None
    except (RecursionError, MemoryError):
        raise ExpressionError("expression is too deeply nested") from None
    return module.body, parsed, lead


def check(
    text: str | float | int | bool,
    names: Mapping[str, Type],
    *,
    constants: Mapping[str, float] | None = None,
    allow_random: bool = True,
    expect: Type | None = None,
) -> Checked:
    """Parse and check `text`; `names` are the variables in scope with their types.

    `constants` (params) are substituted and folded. `expect` is the type the
    context needs (NUM for a reward, BOOL for a condition, a vector for a location).
    """
    tree, parsed, lead = _parse(text)
    if _tree_depth(tree) > MAX_TREE_DEPTH:
        raise ExpressionError(
            f"expression is too long: more than {MAX_TREE_DEPTH} operations chained one after another; "
            "split it into named parts with dynamics.let"
        )
    # layered, not copied: the params check each param with the earlier ones, a copy each would be quadratic
    checker = _Checker(names, ChainMap(cast("MutableMapping[str, float]", constants or {}), CONSTANTS), allow_random)
    try:
        new_tree, typ = checker.visit(tree, 0)
        if expect is not None and not _fits(typ, expect):
            raise ExpressionError(f"expected {expect}, got {typ}", getattr(tree, "col_offset", 0))
    except RecursionError:
        raise ExpressionError("expression is too deeply nested") from None
    except ExpressionError as exc:  # the node's offset counts UTF-8 bytes of the parsed text: as characters of `text`
        exc.offset = lead + len(parsed.encode("utf-8")[: exc.offset].decode("utf-8", "ignore"))
        raise
    checked = Checked(text if isinstance(text, str) else repr(text), new_tree, typ, checker.used, checker.random)
    if isinstance(new_tree, ast.Constant):
        checked.constant = new_tree.value  # type: ignore[assignment]  # the checker only lets numbers and booleans through
    elif isinstance(new_tree, ast.List) and all(isinstance(e, ast.Constant) for e in new_tree.elts):
        checked.constant = tuple(e.value for e in new_tree.elts)  # type: ignore[attr-defined]
    return checked


def _tree_depth(tree: ast.AST) -> int:
    """How deep the syntax tree goes, counted without recursion."""
    deepest, stack = 0, [(tree, 1)]
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node) if isinstance(child, ast.expr))
    return deepest


def _fits(actual: Type, expected: Type) -> bool:
    if expected.kind == "vec" and actual.kind == "vec":
        return expected.size == 0 or expected.size == actual.size
    return actual == expected


def _number(value: float | int, offset: int) -> float:
    if isinstance(value, bool):
        return value
    try:
        number = float(value)
    except OverflowError:
        raise ExpressionError("number is too large", offset) from None
    if math.isnan(number):
        raise ExpressionError("not a number (NaN): expected a finite number", offset)
    if not math.isfinite(number) or abs(number) > MAX_LITERAL:
        raise ExpressionError("number is too large", offset)
    return number


class _Checker:
    def __init__(self, names: Mapping[str, Type], constants: Mapping[str, float], allow_random: bool):
        self.names = names
        self.constants = constants
        self.allow_random = allow_random
        self.used: set[str] = set()
        self.random = False
        self.count = 0

    def fail(self, node: ast.AST, message: str) -> ExpressionError:
        return ExpressionError(message, getattr(node, "col_offset", 0))

    def visit(self, node: ast.AST, depth: int) -> tuple[ast.expr, Type]:
        self.count += 1
        if depth > MAX_DEPTH:
            raise self.fail(node, f"expression is too deeply nested (more than {MAX_DEPTH} levels)")
        if self.count > MAX_NODES:
            raise self.fail(node, f"expression is too large (more than {MAX_NODES} parts)")
        method = getattr(self, "visit_" + type(node).__name__, None)
        if method is None:
            what = _DESCRIBE.get(type(node), f"'{type(node).__name__}'")
            raise self.fail(node, f"{what} not allowed in expressions")
        result = method(node, depth + 1)
        return ast.copy_location(result[0], node), result[1]

    # -- leaves ---------------------------------------------------------------------------------

    def visit_Constant(self, node: ast.Constant, depth: int) -> tuple[ast.expr, Type]:
        value = node.value
        if isinstance(value, bool):
            return ast.Constant(value), BOOL
        if isinstance(value, (int, float)) and not isinstance(value, complex):
            return ast.Constant(_number(value, getattr(node, "col_offset", 0))), NUM
        if isinstance(value, str):
            raise self.fail(node, "text values are not allowed in expressions")
        raise self.fail(node, f"{type(value).__name__} values are not allowed in expressions")

    def visit_Name(self, node: ast.Name, depth: int) -> tuple[ast.expr, Type]:
        name = node.id
        if name in self.names:
            self.used.add(name)
            return ast.Name(name, ast.Load()), self.names[name]
        if name in self.constants:
            value = self.constants[name]
            return ast.Constant(value), (BOOL if isinstance(value, bool) else NUM)
        if name in FUNCTIONS:
            raise self.fail(node, f"'{name}' is a function: call it, e.g. {name}(...)")
        if name in ("True", "False", "None"):
            raise self.fail(node, f"'{name}' is not allowed here")
        known = list(self.names) + [c for c in self.constants if c not in CONSTANTS] + list(CONSTANTS)
        raise self.fail(node, f"unknown name '{name}'" + did_you_mean(name, known))

    # -- operators ------------------------------------------------------------------------------

    def visit_UnaryOp(self, node: ast.UnaryOp, depth: int) -> tuple[ast.expr, Type]:
        operand, typ = self.visit(node.operand, depth)
        if isinstance(node.op, ast.Not):
            self.need(node.operand, typ, BOOL, "'not'")
            return self.fold(ast.UnaryOp(ast.Not(), operand)), BOOL
        if isinstance(node.op, (ast.USub, ast.UAdd)):
            self.need(node.operand, typ, NUM, "'-'")
            return self.fold(ast.UnaryOp(type(node.op)(), operand)), NUM
        raise self.fail(node, "bitwise operators are not allowed in expressions")

    def visit_BinOp(self, node: ast.BinOp, depth: int) -> tuple[ast.expr, Type]:
        # A flat chain `a + b - c + ...` parses as a tree nested to the left: walk that
        # spine in a loop, so a long sum is not "too deeply nested" (nor deep recursion).
        chain = [node]
        while isinstance(chain[-1].left, ast.BinOp):
            chain.append(chain[-1].left)
        first = chain[-1].left
        result, typ = self.visit(first, depth)
        left_node: ast.AST = first
        for link in reversed(chain):
            symbol = _BINOPS.get(type(link.op))
            if symbol is None:
                raise self.fail(link, "bitwise and matrix operators are not allowed in expressions")
            if link is not node:
                self.count += 1
            right, rt = self.visit(link.right, depth)
            self.need(left_node, typ, NUM, f"'{symbol}'")
            self.need(link.right, rt, NUM, f"'{symbol}'")
            result, typ = ast.copy_location(self.fold(ast.BinOp(result, type(link.op)(), right)), link), NUM
            left_node = link
        return result, NUM

    def visit_BoolOp(self, node: ast.BoolOp, depth: int) -> tuple[ast.expr, Type]:
        word = "and" if isinstance(node.op, ast.And) else "or"
        values = []
        for value in node.values:
            new, typ = self.visit(value, depth)
            self.need(value, typ, BOOL, f"'{word}'")
            values.append(new)
        return self.fold(ast.BoolOp(type(node.op)(), values)), BOOL

    def visit_Compare(self, node: ast.Compare, depth: int) -> tuple[ast.expr, Type]:
        left, lt = self.visit(node.left, depth)
        comparators = []
        types = [lt]
        for op in node.ops:
            if type(op) not in _CMPOPS:
                raise self.fail(node, "only <, <=, >, >=, == and != comparisons are allowed")
        for comp in node.comparators:
            new, typ = self.visit(comp, depth)
            comparators.append(new)
            types.append(typ)
        for sub, typ in zip([node.left, *node.comparators], types):
            if typ.kind == "vec":
                raise self.fail(sub, f"cannot compare {typ}")
        if any(not isinstance(op, (ast.Eq, ast.NotEq)) for op in node.ops):
            for sub, typ in zip([node.left, *node.comparators], types):
                self.need(sub, typ, NUM, "an ordering comparison")
        return self.fold(ast.Compare(left, [type(op)() for op in node.ops], comparators)), BOOL

    def visit_IfExp(self, node: ast.IfExp, depth: int) -> tuple[ast.expr, Type]:
        test, tt = self.visit(node.test, depth)
        self.need(node.test, tt, BOOL, "the condition of 'if'")
        body, bt = self.visit(node.body, depth)
        orelse, ot = self.visit(node.orelse, depth)
        if bt != ot:
            raise self.fail(node, f"both branches of 'if ... else' must have the same type (got {bt} and {ot})")
        if isinstance(test, ast.Constant):
            return (body if test.value else orelse), bt
        return ast.IfExp(test, body, orelse), bt

    def visit_List(self, node: ast.List, depth: int) -> tuple[ast.expr, Type]:
        if not node.elts:
            raise self.fail(node, "empty vector")
        if len(node.elts) > MAX_VECTOR:
            raise self.fail(node, f"vector is too long (at most {MAX_VECTOR} elements)")
        elts = []
        for elt in node.elts:
            new, typ = self.visit(elt, depth)
            self.need(elt, typ, NUM, "a vector element")
            elts.append(new)
        return ast.List(elts, ast.Load()), vec(len(elts))

    def visit_Call(self, node: ast.Call, depth: int) -> tuple[ast.expr, Type]:
        if not isinstance(node.func, ast.Name):
            raise self.fail(node, "only the built-in functions can be called, by name")
        name = node.func.id
        func = FUNCTIONS.get(name)
        if func is None:
            kind = "unknown function" if name not in self.names else "not a function:"
            raise self.fail(
                node.func, f"{kind} '{name}'" + did_you_mean(name, FUNCTIONS).replace("names:", "functions:")
            )
        if func.params:
            return self.call_with_params(node, func, depth)
        if node.keywords:
            raise self.fail(node, f"{name}() takes no keyword arguments")
        for arg in node.args:
            if isinstance(arg, ast.Starred):
                raise self.fail(arg, "'*' unpacking not allowed in expressions")
        if func.random and not self.allow_random:
            raise self.fail(node, f"{name}() draws a random number, which is not allowed here")
        n = len(node.args)
        if n < func.min_args or (func.max_args is not None and n > func.max_args):
            if func.max_args is None:
                wanted = f"at least {func.min_args}"
            elif func.min_args == func.max_args:
                wanted = str(func.min_args)
            else:
                wanted = f"{func.min_args} to {func.max_args}"
            raise self.fail(node, f"{name}() takes {wanted} argument{'s' if wanted != '1' else ''}, got {n}")
        args = []
        for i, arg in enumerate(node.args):
            new, typ = self.visit(arg, depth)
            if name == "choice" and n == 1 and typ.kind == "vec":
                pass
            else:
                self.need(arg, typ, NUM, f"argument {i + 1} of {name}()")
            args.append(new)
        if name == "choice" and n == 1 and not (isinstance(args[0], ast.List) or self._is_vec(node.args[0])):
            raise self.fail(node, "choice() needs several values: choice(a, b, ...) or choice([a, b, ...])")
        self.check_constant_arguments(node, name, args)
        if func.random:
            self.random = True
            return ast.Call(ast.Name(name, ast.Load()), args, []), func.returns
        return self.fold(ast.Call(ast.Name(name, ast.Load()), args, [])), func.returns

    def call_with_params(self, node: ast.Call, func: Function, depth: int) -> tuple[ast.expr, Type]:
        """A function with named parameters (``tolerance``): arguments by position, then by keyword, the rest defaulted.

        The checked call passes every parameter by position (a text choice as its index), so the
        generated code, constant folding and the batch's numpy version see an ordinary call.
        """
        name, params = func.name, func.params
        names = [p.name for p in params]
        signature = f"{name}({', '.join(names)})"
        if len(node.args) > len(params):
            raise self.fail(node, f"{signature} takes at most {len(params)} arguments, got {len(node.args)}")
        given: dict[str, ast.expr] = {}
        for param, arg in zip(params, node.args):
            if isinstance(arg, ast.Starred):
                raise self.fail(arg, "'*' unpacking not allowed in expressions")
            given[param.name] = arg
        for kw in node.keywords:
            if kw.arg is None:
                raise self.fail(kw, "'**' unpacking not allowed in expressions")
            if kw.arg not in names:
                raise self.fail(
                    kw,
                    f"{name}() has no argument '{kw.arg}'"
                    + did_you_mean(kw.arg, names).replace("names:", "arguments:"),
                )
            if kw.arg in given:
                raise self.fail(kw, f"{name}() got two values for '{kw.arg}'")
            given[kw.arg] = kw.value
        args: list[ast.expr] = []
        for param in params:
            if param.name not in given:
                if param.default is None:
                    raise self.fail(node, f"{signature} needs '{param.name}'")
                args.append(_default(param))
                continue
            arg = given[param.name]
            if param.choices:
                args.append(self.choice(arg, name, param))
            else:
                new, typ = self.visit(arg, depth)
                self.need(arg, typ, param.type, f"'{param.name}' of {name}()")
                args.append(new)
        if name == "tolerance":
            self.check_tolerance(node, args)
        return self.fold(ast.Call(ast.Name(name, ast.Load()), args, [])), func.returns

    def choice(self, arg: ast.expr, function: str, param: Param) -> ast.expr:
        """A text argument, one of the parameter's choices, as its index (the only text an expression may hold)."""
        options = ", ".join(f'"{c}"' for c in param.choices)
        if not (isinstance(arg, ast.Constant) and isinstance(arg.value, str)):
            raise self.fail(arg, f"'{param.name}' of {function}() is one of {options}, written in quotes")
        if arg.value not in param.choices:
            raise self.fail(
                arg,
                f"'{param.name}' of {function}() has no choice \"{arg.value}\""
                + did_you_mean(arg.value, param.choices).replace("names:", "choices:"),
            )
        return ast.Constant(float(param.choices.index(arg.value)))

    def check_tolerance(self, node: ast.Call, args: list[ast.expr]) -> None:
        """dm_control's refusals of constant arguments (bounds out of order, a negative margin, a value at the margin out of range), now."""
        bounds, margin, sigmoid, value = args[1:]

        def constant(tree: ast.expr, otherwise: float) -> float:
            return float(tree.value) if isinstance(tree, ast.Constant) and isinstance(tree.value, float) else otherwise

        lower, upper = (
            (constant(e, f) for e, f in zip(bounds.elts, (-math.inf, math.inf)))
            if isinstance(bounds, ast.List)
            else (-math.inf, math.inf)
        )
        why = tolerance_problem(
            lower, upper, constant(margin, 1.0), SIGMOIDS[int(constant(sigmoid, 0))], constant(value, 0.5)
        )
        if why:
            raise self.fail(node, why)

    def check_constant_arguments(self, node: ast.Call, name: str, args: list[ast.expr]) -> None:
        """Constant arguments that cannot work (a negative spread, bounds in the wrong order) fail now, not at run time."""
        values = [a.value if isinstance(a, ast.Constant) else None for a in args]
        if name == "normal" and isinstance(values[1], float) and values[1] < 0:
            raise self.fail(node.args[1], f"normal(mean, std) needs std >= 0, got {values[1]:g}")
        bounds = {"uniform": (0, 1), "randint": (0, 1), "clip": (1, 2)}.get(name)
        if bounds is not None:
            low, high = (values[i] for i in bounds)
            if isinstance(low, float) and isinstance(high, float) and low > high:
                words = "clip(x, low, high)" if name == "clip" else f"{name}(low, high)"
                raise self.fail(node, f"{words} needs low <= high, got {low:g} and {high:g}")

    def _is_vec(self, node: ast.AST) -> bool:
        return isinstance(node, ast.Name) and self.names.get(node.id, NUM).kind == "vec"

    # -- helpers --------------------------------------------------------------------------------

    def need(self, node: ast.AST, actual: Type, expected: Type, where: str) -> None:
        if actual != expected:
            raise self.fail(node, f"{where} needs {expected}, got {actual}")

    def fold(self, node: ast.expr) -> ast.expr:
        """Evaluate a subexpression whose operands are all constants, now."""
        children = [c for c in ast.iter_child_nodes(node) if isinstance(c, ast.expr)]
        if isinstance(node, ast.Call):
            children = list(node.args)
        if not all(isinstance(c, ast.Constant) for c in children):
            return node
        from visualenv.expr.codegen import evaluate_constant

        try:
            value = evaluate_constant(node)
        except ZeroDivisionError:
            raise self.fail(node, "division by zero") from None
        except OverflowError:
            raise self.fail(node, "numeric overflow: the result is too large") from None
        except ValueError as exc:
            raise self.fail(node, f"math error: {exc}") from None
        if isinstance(value, float) and math.isnan(value):
            raise self.fail(node, "math error: the result is not a number (NaN)")
        if (
            isinstance(value, float)
            and not math.isfinite(value)
            and not any(
                isinstance(c, ast.Constant) and isinstance(c.value, float) and math.isinf(c.value) for c in children
            )
        ):
            raise self.fail(node, "numeric overflow: the result is not finite")
        return ast.Constant(value)


def _default(param: Param) -> ast.expr:
    """A parameter's default as a checked tree: a number, a vector literal, or a choice's index."""
    if param.choices:
        return ast.Constant(float(param.choices.index(param.default)))
    if isinstance(param.default, tuple):
        return ast.List([ast.Constant(float(v)) for v in param.default], ast.Load())
    return ast.Constant(float(param.default))
