"""Every use of a dependency's internals lives in visualenv/compat/: the package is searched for them."""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

PACKAGE = Path(__file__).parents[2] / "visualenv"
#: names that reach past a dependency's documented API: C calls through ctypes, glibc's allocator, frame inspection
INTERNAL_NAMES = {
    "ctypes",
    "CDLL",
    "cdll",
    "cffi",
    "mallopt",
    "malloc_trim",
    "_getframe",
    "currentframe",
    "getouterframes",
    "f_locals",
    "f_back",
}
#: MKL's service functions (mkl_cbwr_set, mkl_serv_cbwr_get, ...), by name or looked up by a string
MKL_SERVICE = re.compile(r"^mkl_\w+$")
#: files that still hold such uses, with the change that removes them (made on another branch): each entry must still be
#: true, so the list shrinks as those branches are merged and this test then names the entry to remove
PENDING: dict[str, str] = {}


def internal_uses(text: str, name: str) -> list[str]:
    """`name:line: word` for each use in code (names and plain strings; comments and docstrings are prose)."""
    uses = []
    tokens = tokenize.generate_tokens(io.StringIO(text).readline)
    for token in tokens:
        if token.type == tokenize.NAME:
            word = token.string
        elif token.type == tokenize.STRING and re.fullmatch(r"[rbuRBU]?(['\"])\w+\1", token.string):
            word = token.string.strip("rbuRBU")[1:-1]
        else:
            continue
        if word in INTERNAL_NAMES or MKL_SERVICE.match(word):
            uses.append(f"{name}:{token.start[0]}: {word}")
    return uses


def test_dependency_internals_are_used_only_in_the_compat_package():
    outside = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        relative = path.relative_to(PACKAGE).as_posix()
        if relative.startswith("compat/"):
            continue
        uses = internal_uses(path.read_text(encoding="utf-8"), relative)
        if uses:
            outside[relative] = uses
    unexpected = {name: uses for name, uses in outside.items() if name not in PENDING}
    assert not unexpected, "move these into visualenv/compat/ (one module per dependency):\n" + "\n".join(
        use for uses in unexpected.values() for use in uses
    )
    fixed = sorted(set(PENDING) - set(outside))
    assert not fixed, f"no longer uses a dependency's internals: remove it from PENDING: {fixed}"


def test_the_search_finds_what_it_looks_for():
    """The search itself: each kind of use is found in code, and prose about them is not."""
    text = (
        '"""ctypes and mallopt are named in prose."""\n'
        "import ctypes  # a comment naming malloc_trim\n"
        "frame = sys._getframe(1)\n"
        "lib = getattr(torch_lib, 'mkl_serv_cbwr_set')\n"
    )
    assert internal_uses(text, "sample.py") == [
        "sample.py:2: ctypes",
        "sample.py:3: _getframe",
        "sample.py:4: mkl_serv_cbwr_set",
    ]


# -- private names of other packages -------------------------------------------------------------------------------

#: names with a leading underscore that are documented public API (namedtuple's methods, os._exit)
PUBLIC_UNDERSCORED = {"_asdict", "_replace", "_make", "_fields", "_field_defaults", "_exit"}
#: the names through which a class's code assigns its own attributes
OWNERS = ("self", "cls")
#: the built-ins that reach an attribute by its name as a string
ATTRIBUTE_CALLS = ("getattr", "setattr", "hasattr", "delattr")


def private(name: str) -> bool:
    """`_name`, not `__dunder__` (a sunder name such as Enum's `_value2member_map_` is private)."""
    dunder = name.startswith("__") and name.endswith("__")
    return name.startswith("_") and not dunder and name not in PUBLIC_UNDERSCORED


def own_private_names(tree: ast.AST) -> set[str]:
    """The private names a module defines: functions, classes, names assigned (module level, class bodies, functions:
    fields included), attributes assigned on ``self`` or ``cls``, and aliases of imports."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign, ast.For, ast.With)):
            if isinstance(node, ast.Assign):
                targets = node.targets
            elif isinstance(node, ast.With):
                targets = [item.optional_vars for item in node.items if item.optional_vars]
            else:
                targets = [node.target]
            for part in (part for target in targets for part in ast.walk(target)):
                if isinstance(part, ast.Name):
                    names.add(part.id)
                elif isinstance(part, ast.Attribute) and isinstance(part.value, ast.Name) and part.value.id in OWNERS:
                    names.add(part.attr)
        elif isinstance(node, ast.alias) and node.asname:
            names.add(node.asname)
    return {name for name in names if private(name)}


def attribute_named(call: ast.Call) -> str:
    """The attribute ``getattr(X, "name")`` and the like reach, by a name written in the call; else ""."""
    if isinstance(call.func, ast.Name) and call.func.id in ATTRIBUTE_CALLS and len(call.args) > 1:
        name = call.args[1]
        if isinstance(name, ast.Constant) and isinstance(name.value, str):
            return name.value
    return ""


def private_uses(tree: ast.AST, name: str, own: set[str]) -> list[str]:
    """`name:line: what` for each import of another package's private module or name, and each access ``X._name``
    (``getattr(X, "_name")`` and the like included) to a private name visualenv does not define."""
    found = []
    for node in ast.walk(tree):
        what = None
        if isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names if alias.name.split(".")[0] != "visualenv"]
            what = next((f"import {m}" for m in modules if any(private(part) for part in m.split(".")[1:])), None)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            parts, names = node.module.split("."), [alias.name for alias in node.names]
            if parts[0] != "visualenv" and (any(private(part) for part in parts[1:]) or any(private(n) for n in names)):
                what = f"from {node.module} import {', '.join(names)}"
        elif isinstance(node, ast.Attribute) and private(node.attr) and node.attr not in own:
            what = f"{ast.unparse(node.value)}.{node.attr}"
        elif isinstance(node, ast.Call) and private(named := attribute_named(node)) and named not in own:
            what = f"{ast.unparse(node.func)}({ast.unparse(node.args[0])}, {named!r})"
        if what is not None:
            found.append(f"{name}:{node.lineno}: {what}")
    return sorted(found, key=lambda use: int(use.split(":")[1]))


def package_trees() -> dict[str, ast.AST]:
    paths = sorted(PACKAGE.rglob("*.py"))
    return {path.relative_to(PACKAGE).as_posix(): ast.parse(path.read_text(encoding="utf-8")) for path in paths}


def test_no_private_name_of_another_package_is_used_outside_the_compat_package():
    """Another package's private modules, functions and attributes are reached from visualenv/compat/ alone, where each
    is named, gated on the versions checked and tested."""
    trees = package_trees()
    own = set().union(*(own_private_names(tree) for tree in trees.values()))
    outside = {name: tree for name, tree in trees.items() if not name.startswith("compat/")}
    uses = [use for name, tree in outside.items() for use in private_uses(tree, name, own)]
    assert not uses, "move these into the dependency's module in visualenv/compat/:\n" + "\n".join(uses)


def test_the_private_name_search_finds_what_it_looks_for():
    """The search itself, on a planted module: another package's private module and attributes are found (with their
    lines), visualenv's own private names and documented underscored names are not."""
    planted = (
        "import torch\n"
        "from ray._private import services\n"
        "from visualenv.physics import _helper\n"
        "import gymnasium.envs._impl as impl\n"
        "from torch import _dynamo\n"
        "class Probe:\n"
        "    _field: int = 0\n"
        "    def __init__(self) -> None:\n"
        "        self._mine = torch._C\n"
        "        self.__dict__.update(self._mine._asdict())\n"
        "    def _helper(self, space, other) -> None:\n"
        "        other._mine, other._field = self._helper, space._np_random\n"
        "        space._np_random = getattr(space, '_np_random', None)\n"
    )
    tree = ast.parse(planted)
    own = own_private_names(tree)
    assert own == {"_field", "_mine", "_helper"}
    assert private_uses(tree, "planted.py", own) == [
        "planted.py:2: from ray._private import services",
        "planted.py:4: import gymnasium.envs._impl",
        "planted.py:5: from torch import _dynamo",
        "planted.py:9: torch._C",
        "planted.py:12: space._np_random",
        "planted.py:13: space._np_random",
        "planted.py:13: getattr(space, '_np_random')",
    ]
