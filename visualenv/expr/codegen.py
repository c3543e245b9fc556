"""Turn checked expression trees into Python functions, without ever using text.

The compiler assembles whole per-step functions from checked trees: every
user name becomes a local ``_v_<name>``, every function a global ``_f_<name>``
bound to the implementation in the function table, vectors become tuples. The
assembled :mod:`ast` module is compiled with empty builtins. Because the trees
were built by :mod:`visualenv.expr.checker` from allowed nodes only, nothing in
a spec can reach Python's attributes, imports or builtins.

Each generated statement that evaluates a spec expression gets a line number of
its own, and the builder hands out a :class:`LineMap` from those numbers to the
spec sites: the one place that knows how generated lines were numbered, asked
whenever a runtime fault must name the expression (and spec line) that raised it.
"""

from __future__ import annotations

import ast
import copy
from dataclasses import dataclass, field
from types import CodeType, TracebackType
from typing import Any, Callable, Mapping, Protocol

from visualenv.expr.functions import FUNCTIONS

VAR_PREFIX = "_v_"
FUNC_PREFIX = "_f_"
POW = "_pow"


def power(base: float, exponent: float) -> float:
    """``base ** exponent`` for numbers; a negative base to a fractional power is a domain error, not a complex number."""
    result = base**exponent
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


class Checked(Protocol):
    """What code generation reads of a checked expression (:class:`visualenv.expr.checker.Checked`)."""

    text: str
    tree: ast.expr
    names: set[str]


@dataclass
class Site:
    """Where a generated statement came from, for runtime error messages."""

    what: str  # e.g. "dynamics.update.x"
    text: str  # the expression text
    names: tuple[str, ...] = ()

    @classmethod
    def of(cls, path: tuple, checked: Checked) -> "Site":
        """The site of a checked expression found at a spec path such as ``("dynamics", "let", "x")``."""
        return cls(".".join(map(str, path)), checked.text, tuple(sorted(checked.names)))


#: the line of the ``def``: statements without a site share it, so no site ever maps to it
_DEF_LINE = 1


@dataclass(frozen=True)
class LineMap:
    """Which spec site each line of one generated function came from.

    The generated code alone knows how its lines were numbered, so callers ask
    this map, never do arithmetic on line numbers (jinja2's
    ``Template.get_corresponding_lineno`` plays the same part for templates).
    """

    filename: str  # the co_filename of the generated code, which tells its frames apart
    sites: tuple[Site, ...]  # sites[i] is line _DEF_LINE + 1 + i

    def site_at(self, lineno: int) -> Site | None:
        """The site a line number of the generated function (a frame's ``f_lineno``) came from, or None."""
        index = lineno - _DEF_LINE - 1
        return self.sites[index] if 0 <= index < len(self.sites) else None

    def site_in(self, tb: TracebackType | None) -> Site | None:
        """The site of the innermost frame of this function in a traceback; None if the fault was raised elsewhere."""
        line = None
        while tb is not None:
            if tb.tb_frame.f_code.co_filename == self.filename:
                line = tb.tb_lineno
            tb = tb.tb_next
        return self.site_at(line) if line is not None else None

    def find(self, what: str) -> Site | None:
        """The first site of a spec field (e.g. ``"reward"``), for a fault found after the function returned."""
        return next((s for s in self.sites if s.what == what), None)


@dataclass
class FunctionBuilder:
    """Collects statements and compiles them into one function."""

    name: str
    args: list[str]
    body: list[ast.stmt] = field(default_factory=list)
    sites: list[Site] = field(default_factory=list)
    #: the body compiled once for every env's :meth:`build` (a batch builds a set of functions per env), and the
    #: statements it was compiled from: the compiler also edits ``body`` directly (e.g. wraps statements in a loop)
    _code: CodeType | None = field(default=None, init=False, repr=False)
    _compiled_from: tuple[int, ...] = field(default=(), init=False, repr=False)

    @property
    def filename(self) -> str:
        return f"<visualenv:{self.name}>"

    def line_map(self) -> LineMap:
        """The map from this function's line numbers to the spec sites they evaluate."""
        return LineMap(self.filename, tuple(self.sites))

    def _line(self, site: Site | None) -> int:
        if site is None:
            return _DEF_LINE
        self.sites.append(site)
        return _DEF_LINE + len(self.sites)

    def assign(self, target: str, value: ast.expr, site: Site | None = None) -> None:
        stmt = ast.Assign([ast.Name(target, ast.Store())], value)
        self._add(stmt, site)

    def assign_checked(self, target: str, path: tuple, checked: Checked) -> None:
        """``target = <checked expression>``, its site the spec path it was written at."""
        self.assign(target, lower(checked.tree), Site.of(path, checked))

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
                node.lineno = line
                node.end_lineno = line  # type: ignore[attr-defined]
                node.col_offset = 0  # type: ignore[attr-defined]
                node.end_col_offset = 0  # type: ignore[attr-defined]
        self.body.append(stmt)

    def returns(self, value: ast.expr) -> None:
        self._add(ast.Return(value), None)

    def build(self, env: dict[str, Any]) -> Callable[..., Any]:
        """The function, its globals `env` (each env's random source and simulation): compiled once for all."""
        statements = tuple(map(id, self.body))
        if self._code is None or statements != self._compiled_from:
            self._code, self._compiled_from = self._compile(), statements
        namespace = dict(env)
        exec(self._code, namespace)  # noqa: S102 - compiles a tree assembled from checked nodes
        return namespace[self.name]

    def _compile(self) -> CodeType:
        args = ast.arguments(
            posonlyargs=[], args=[ast.arg(a) for a in self.args], kwonlyargs=[], kw_defaults=[], defaults=[]
        )
        fn = ast.FunctionDef(self.name, args, self.body or [ast.Pass()], [], None, type_params=[])  # type: ignore[call-arg]  # 3.12 field, harmless on 3.11
        module = ast.Module([fn], type_ignores=[])
        ast.fix_missing_locations(module)
        fn.lineno = _DEF_LINE
        return compile(module, self.filename, "exec")


def name(identifier: str) -> ast.Name:
    return ast.Name(identifier, ast.Load())


def const(value: Any) -> ast.Constant:
    return ast.Constant(value)


def tuple_of(items: list[ast.expr]) -> ast.expr:
    return ast.Tuple(items, ast.Load())
