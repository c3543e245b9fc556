"""Turn checked expression trees into Python functions, without ever using text.

The compiler assembles whole per-step functions from checked trees: every
user name becomes a local ``_v_<name>``, every function a global ``_f_<name>``
bound to the implementation in the function table, vectors become tuples. The
assembled :mod:`ast` module is compiled with empty builtins. Because the trees
were built by :mod:`visualenv.expr.checker` from allowed nodes only, nothing in
a spec can reach Python's attributes, imports or builtins.

Each generated statement carries a distinct line number, so a runtime fault
can be traced back to the expression (and spec line) that raised it.
"""

from __future__ import annotations

import ast
import copy
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from visualenv.expr.functions import FUNCTIONS

VAR_PREFIX = "_v_"
FUNC_PREFIX = "_f_"
POW = "_pow"


def power(base: float, exponent: float) -> float:
    """``base ** exponent`` for numbers; a negative base to a fractional power is a domain error, not a complex number."""
    result = base ** exponent
    if isinstance(result, complex):
        raise ValueError("a negative number to a fractional power")
    return result


def local(name: str) -> str:
    return VAR_PREFIX + name


class _Rename(ast.NodeTransformer):
    def visit_Call(self, node: ast.Call) -> ast.AST:
        node.args = [self.visit(a) for a in node.args]
        assert isinstance(node.func, ast.Name)
        node.func = ast.Name(FUNC_PREFIX + node.func.id, ast.Load())
        return node

    def visit_Name(self, node: ast.Name) -> ast.AST:
        return ast.Name(VAR_PREFIX + node.id, ast.Load())

    def visit_BinOp(self, node: ast.BinOp) -> ast.AST:
        left, right = self.visit(node.left), self.visit(node.right)
        if isinstance(node.op, ast.Pow):
            return ast.Call(ast.Name(POW, ast.Load()), [left, right], [])
        return ast.BinOp(left, node.op, right)

    def visit_List(self, node: ast.List) -> ast.AST:
        return ast.Tuple([self.visit(e) for e in node.elts], ast.Load())


def lower(tree: ast.expr) -> ast.expr:
    """A checked tree in the names the generated code uses."""
    return _Rename().visit(copy.deepcopy(tree))


def function_globals(random_impls: Mapping[str, Callable[..., Any]] | None = None) -> dict[str, Any]:
    """The only globals generated code sees: the function table, and no builtins."""
    env: dict[str, Any] = {"__builtins__": {}, POW: power}
    for name, func in FUNCTIONS.items():
        impl = func.impl if func.impl is not None else (random_impls or {}).get(name)
        if impl is not None:
            env[FUNC_PREFIX + name] = impl
    return env


def evaluate_constant(tree: ast.expr) -> Any:
    """Evaluate a tree of constants and pure function calls (constant folding)."""
    code = compile(ast.fix_missing_locations(ast.Expression(lower(tree))), "<constant>", "eval")
    return eval(code, function_globals())  # noqa: S307 - a checked tree of constants, not text


@dataclass
class Site:
    """Where a generated statement came from, for runtime error messages."""

    what: str  # e.g. "dynamics.update.x"
    text: str  # the expression text
    names: tuple[str, ...] = ()


@dataclass
class FunctionBuilder:
    """Collects statements and compiles them into one function."""

    name: str
    args: list[str]
    body: list[ast.stmt] = field(default_factory=list)
    sites: list[Site] = field(default_factory=list)

    def _line(self, site: Site | None) -> int:
        if site is None:
            return 1
        self.sites.append(site)
        return len(self.sites) + 1  # line 1 is the def

    def assign(self, target: str, value: ast.expr, site: Site | None = None) -> None:
        stmt = ast.Assign([ast.Name(target, ast.Store())], value)
        self._add(stmt, site)

    def unpack(self, targets: list[str], source: str) -> None:
        if not targets:
            return
        if len(targets) == 1:
            value: ast.expr = ast.Subscript(ast.Name(source, ast.Load()), ast.Constant(0), ast.Load())
            self._add(ast.Assign([ast.Name(targets[0], ast.Store())], value), None)
            return
        tgt = ast.Tuple([ast.Name(t, ast.Store()) for t in targets], ast.Store())
        self._add(ast.Assign([tgt], ast.Name(source, ast.Load())), None)

    def add(self, stmt: ast.stmt, site: Site | None = None) -> None:
        self._add(stmt, site)

    def _add(self, stmt: ast.stmt, site: Site | None) -> None:
        line = self._line(site)
        for node in ast.walk(stmt):
            if hasattr(node, "lineno") or isinstance(node, (ast.expr, ast.stmt)):
                node.lineno = line  # type: ignore[attr-defined]
                node.end_lineno = line  # type: ignore[attr-defined]
                node.col_offset = 0  # type: ignore[attr-defined]
                node.end_col_offset = 0  # type: ignore[attr-defined]
        self.body.append(stmt)

    def returns(self, value: ast.expr) -> None:
        self._add(ast.Return(value), None)

    def build(self, env: dict[str, Any]) -> Callable[..., Any]:
        args = ast.arguments(posonlyargs=[], args=[ast.arg(a) for a in self.args], kwonlyargs=[], kw_defaults=[], defaults=[])
        fn = ast.FunctionDef(self.name, args, self.body or [ast.Pass()], [], None, type_params=[])  # type: ignore[call-arg]  # 3.12 field, harmless on 3.11
        module = ast.Module([fn], type_ignores=[])
        ast.fix_missing_locations(module)
        fn.lineno = 1
        code = compile(module, f"<visualenv:{self.name}>", "exec")
        namespace = dict(env)
        exec(code, namespace)  # noqa: S102 - compiles a tree assembled from checked nodes
        return namespace[self.name]


def name(identifier: str) -> ast.Name:
    return ast.Name(identifier, ast.Load())


def const(value: Any) -> ast.Constant:
    return ast.Constant(value)


def tuple_of(items: list[ast.expr]) -> ast.expr:
    return ast.Tuple(items, ast.Load())
