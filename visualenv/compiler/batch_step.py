"""The generated step and bind functions, rewritten to run N envs at once on numpy arrays.

The compiler generates scalar functions (one env, Python floats, ``if`` chains).
A batch of envs needs the same arithmetic on columns: every state variable an
array of N values. This module rewrites the scalar functions' syntax trees,
statement by statement, so that the spec's expressions are never parsed twice
and both versions compute the same thing:

* a conditional expression ``a if c else b`` becomes ``where(c, a, b)``;
  ``and``/``or``/``not`` and chained comparisons become element-wise logic;
* an ``if`` statement (the chosen action's inputs, the outcome chain, a
  milestone) becomes masked assignments: ``x = where(mask, new, x)``;
* the function table is swapped for one on columns (``sin`` -> ``np.sin``, ...), which gives
  Python's values to the bit (:mod:`visualenv.compiler.batch_functions`).

Both branches of a conditional are evaluated for every env, so an expression
the scalar code would never reach may divide by zero, and an expression it does
reach may raise where numpy's gives a number (``clip(1 / x, -1, 1)`` at x = 0 is
ZeroDivisionError in Python, 1.0 in numpy). So divisions and the functions note
each value Python raises on, and a batch runs these functions under
:func:`~visualenv.compiler.batch_functions.float_errors` (numpy's warnings off,
the notes collected): after a step in which one was noted, or whose result for an
env is not finite, the scalar function steps those envs again (every env, when a
value was noted: the element-wise code cannot say whose), which gives the same
value or the located fault.

Random draws (``uniform``...) and ``dynamics.python`` read one env's generator
or call one env's hook: a step that uses them is not vectorised
(:func:`vectorize` returns None and the batch steps its envs one by one).
"""

from __future__ import annotations

import ast
import copy
import functools
from typing import Any, Callable

import numpy as np

from visualenv.expr.codegen import FUNC_PREFIX, POW, FunctionBuilder
from visualenv.compiler.batch_functions import OPERATORS, vector_functions
from visualenv.expr.functions import FUNCTIONS

WHERE, ALL, ANY, NOT = "_vwhere", "_vall", "_vany", "_vnot"


def _where(mask: Any, a: Any, b: Any) -> Any:
    """Element-wise choice that also takes vectors (tuples of columns)."""
    if isinstance(a, tuple) or isinstance(b, tuple):
        size = len(a) if isinstance(a, tuple) else len(b)
        a = a if isinstance(a, tuple) else (a,) * size
        b = b if isinstance(b, tuple) else (b,) * size
        return tuple(np.where(mask, x, y) for x, y in zip(a, b))
    return np.where(mask, a, b)


def _all(*values: Any) -> Any:
    return functools.reduce(np.logical_and, values)


def _any(*values: Any) -> Any:
    return functools.reduce(np.logical_or, values)


#: names whose presence in a generated function keeps it scalar (one env's generator or hook)
_SCALAR_ONLY = {FUNC_PREFIX + n for n, f in FUNCTIONS.items() if f.random} | {"_python_dynamics", "_random"}


def vector_globals() -> dict[str, Any]:
    """The only globals a vectorised function sees: the function table on columns and the element-wise helpers."""
    table = vector_functions()
    env: dict[str, Any] = {
        "__builtins__": {},
        POW: table["pow"],
        WHERE: _where,
        ALL: _all,
        ANY: _any,
        NOT: np.logical_not,
    }
    env.update({FUNC_PREFIX + n: f for n, f in table.items() if n != "pow"})
    env.update({f"_v{op.__name__}": f for op, f in OPERATORS.items()})
    return env


def _call(func: str, args: list[ast.expr]) -> ast.Call:
    return ast.Call(ast.Name(func, ast.Load()), args, [])


class _Expressions(ast.NodeTransformer):
    """Expressions to their element-wise form."""

    def visit_BinOp(self, node: ast.BinOp) -> ast.AST:
        left, right = self.visit(node.left), self.visit(node.right)
        constant = isinstance(right, ast.Constant) and isinstance(right.value, (int, float)) and right.value != 0
        # a division: by zero, Python raises (noted), numpy gives a number
        if type(node.op) in OPERATORS and not constant:
            return _call(f"_v{type(node.op).__name__}", [left, right])
        return ast.BinOp(left, node.op, right)

    def visit_IfExp(self, node: ast.IfExp) -> ast.AST:
        return _call(WHERE, [self.visit(node.test), self.visit(node.body), self.visit(node.orelse)])

    def visit_BoolOp(self, node: ast.BoolOp) -> ast.AST:
        return _call(ALL if isinstance(node.op, ast.And) else ANY, [self.visit(v) for v in node.values])

    def visit_UnaryOp(self, node: ast.UnaryOp) -> ast.AST:
        operand = self.visit(node.operand)
        if isinstance(node.op, ast.Not):
            return _call(NOT, [operand])
        return ast.UnaryOp(node.op, operand)

    def visit_Compare(self, node: ast.Compare) -> ast.AST:
        left = self.visit(node.left)
        rights = [self.visit(c) for c in node.comparators]
        pairs: list[ast.expr] = []
        for op, right in zip(node.ops, rights):
            pairs.append(ast.Compare(left, [op], [right]))
            left = right
        return pairs[0] if len(pairs) == 1 else _call(ALL, pairs)


class _Statements:
    """Statements under a mask: ``if`` becomes masked assignment."""

    def __init__(self) -> None:
        self.masks = 0

    def rewrite(self, stmts: list[ast.stmt], mask: ast.expr | None) -> list[ast.stmt]:
        out: list[ast.stmt] = []
        for stmt in stmts:
            out.extend(self.statement(stmt, mask))
        return out

    def statement(self, stmt: ast.stmt, mask: ast.expr | None) -> list[ast.stmt]:
        expr = _Expressions().visit
        if isinstance(stmt, ast.Pass):
            return []
        if isinstance(stmt, ast.Return):
            return [ast.Return(expr(stmt.value) if stmt.value is not None else None)]
        if isinstance(stmt, ast.Assign):
            value = expr(stmt.value)
            target = stmt.targets[0]
            if mask is None or not isinstance(target, ast.Name):
                return [ast.Assign(stmt.targets, value)]
            return [_masked(target.id, value, mask)]
        if isinstance(stmt, ast.AugAssign) and isinstance(stmt.target, ast.Name):
            value = ast.BinOp(ast.Name(stmt.target.id, ast.Load()), stmt.op, expr(stmt.value))
            if mask is None:
                return [ast.Assign([ast.Name(stmt.target.id, ast.Store())], value)]
            return [_masked(stmt.target.id, value, mask)]
        if isinstance(stmt, ast.Expr) and mask is None:  # a call for its effect: a physics spec's MuJoCo step
            return [ast.Expr(expr(stmt.value))]
        if isinstance(stmt, ast.If):
            self.masks += 1
            taken, other = f"_mask{self.masks}", f"_else{self.masks}"
            test = expr(stmt.test)
            both = test if mask is None else _call(ALL, [mask, test])
            rest = _call(NOT, [test]) if mask is None else _call(ALL, [mask, _call(NOT, [test])])
            out: list[ast.stmt] = [ast.Assign([ast.Name(taken, ast.Store())], both)]
            if stmt.orelse:
                out.append(ast.Assign([ast.Name(other, ast.Store())], rest))
            out += self.rewrite(stmt.body, ast.Name(taken, ast.Load()))
            if stmt.orelse:
                out += self.rewrite(stmt.orelse, ast.Name(other, ast.Load()))
            return out
        raise TypeError(f"cannot vectorise a {type(stmt).__name__} statement")  # the compiler generates no others


def _masked(name: str, value: ast.expr, mask: ast.expr) -> ast.stmt:
    return ast.Assign([ast.Name(name, ast.Store())], _call(WHERE, [mask, value, ast.Name(name, ast.Load())]))


def vectorizable(builder: FunctionBuilder) -> bool:
    """Whether a generated function reads nothing that belongs to one env (a random draw, the Python hook)."""
    return not any(isinstance(n, ast.Name) and n.id in _SCALAR_ONLY for stmt in builder.body for n in ast.walk(stmt))


def vectorize(builder: FunctionBuilder, extra: dict[str, Any] | None = None) -> Callable[..., Any] | None:
    """The element-wise version of a generated function (same arguments, columns for numbers), or None if it must stay scalar.

    `extra` adds globals: a physics spec's column reads and batch step (:mod:`visualenv.physics.batch`).
    """
    if not vectorizable(builder):
        return None
    body = _Statements().rewrite([copy.deepcopy(s) for s in builder.body], None)
    vector = FunctionBuilder(builder.name + "_batch", list(builder.args))
    for stmt in body:
        vector.add(stmt)
    return vector.build({**vector_globals(), **(extra or {})})
