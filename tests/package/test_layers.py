"""The package's layers: imports point one way (down the layers drawn in docs/architecture.md) and never form a cycle.

Every import counts, function-level ones included: a lazy import is still a dependency.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "visualenv"

#: each module's layer, by its longest matching prefix; a module may import its own layer or lower ones
LAYERS = {
    "visualenv.errors": 0,
    "visualenv.files": 0,
    "visualenv.bindables": 0,
    "visualenv.source_map": 0,
    "visualenv.versions": 0,
    "visualenv.compat": 0,
    "visualenv.spec": 1,
    "visualenv.expr": 1,
    "visualenv.physics": 1,
    "visualenv.render": 2,
    "visualenv.compiler": 3,
    "visualenv.env": 4,
    "visualenv.dmc": 4,  # dm_env's interface over the DMC ids
    "visualenv.train": 5,
    "visualenv.tools": 6,
    # the viewer steps envs and loads agents; render_mode="human" reaches it through a hook (visualenv.env.human)
    "visualenv.viewer": 6,
    "visualenv.cli": 7,
    "visualenv": 7,
}


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in PACKAGE.rglob("*.py") if "specs" not in p.parts}


def imports(path: Path, known: set[str]) -> set[str]:
    """The visualenv modules `path` imports, anywhere in its body."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.split(".")[0] == "visualenv")
        elif (
            isinstance(node, ast.ImportFrom)
            and node.module
            and node.module.split(".")[0] == "visualenv"
            and node.level == 0
        ):
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                found.add(sub if sub in known else node.module)
    return found


def layer(name: str) -> int:
    best = max((prefix for prefix in LAYERS if name == prefix or name.startswith(prefix + ".")), key=len)
    return LAYERS[best]


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: imports(path, set(known)) - {name} for name, path in known.items()}


def test_every_module_has_a_layer() -> None:
    unplaced = [
        name
        for name in modules()
        if not any(name == p or name.startswith(p + ".") for p in LAYERS if p != "visualenv") and name != "visualenv"
    ]
    assert unplaced == [], f"modules outside the layers: put them in a layer's package: {unplaced}"


def test_imports_point_down() -> None:
    upward = sorted(
        f"{a} ({layer(a)}) imports {b} ({layer(b)})"
        for a, targets in graph().items()
        for b in targets
        if layer(b) > layer(a)
    )
    assert upward == [], "\n".join(upward)


def find_cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Cycles met by a depth-first walk (each one as a list of modules, first == last)."""
    cycles: list[list[str]] = []
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(edges.get(node, ())):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt) :] + [nxt])
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for node in sorted(edges):
        if node not in state:
            visit(node)
    return cycles


def test_no_import_cycle() -> None:
    cycles = find_cycles(graph())
    assert cycles == [], "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_the_checks_see_a_cycle_and_an_upward_import() -> None:
    """Neither check is vacuous: a planted cycle is found, and the graph holds the lazy imports."""
    assert find_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == [["a", "b", "c", "a"]]
    edges = graph()
    assert "visualenv.train.rllib_setup" in edges["visualenv.train.model_files"]  # a function-level import
    assert layer("visualenv.train.play") == 5 and layer("visualenv.env.make") == 4 and layer("visualenv") == 7


def test_physics_layer_never_imports_bpy_or_upper_layers() -> None:
    """The physics layer (MuJoCo) sits beside expr: no Blender, no compiler, env or render; it imports only the foundation
    it needs (errors; files, which finds a package's files without importing it; compat, where MuJoCo's version gates
    live, save Blender's) and itself."""
    for name, path in modules().items():
        if name.startswith("visualenv.physics"):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
            imported |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
            assert not any(m.split(".")[0] == "bpy" for m in imported), (name, imported)
            ours = {m for m in imported if m.split(".")[0] == "visualenv"}
            foundation = ("visualenv.errors", "visualenv.files")
            allowed = [m for m in ours if m in foundation or m.startswith(("visualenv.physics", "visualenv.compat"))]
            assert sorted(allowed) == sorted(ours) and "visualenv.compat.blender" not in ours, (name, ours)


#: the most lines a module may hold: past it, a module does more than one job (split it by job)
MAX_MODULE_LINES = 600


def test_no_module_is_over_the_size_limit() -> None:
    big = {
        name: n
        for name, path in modules().items()
        if (n := len(path.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert big == {}, f"split these by job (at most {MAX_MODULE_LINES} lines a module): {big}"


def private_imports(path: Path) -> list[str]:
    """The private names (``_name``) `path` imports from another visualenv module."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "visualenv":
            found += [
                f"{node.module}.{a.name}" for a in node.names if a.name.startswith("_") and not a.name.startswith("__")
            ]
    return found


def test_no_module_imports_another_modules_private_names(tmp_path: Path) -> None:
    """What one module shares with another is public and documented; a private name stays in its module."""
    found = {name: names for name, path in modules().items() if (names := private_imports(path))}
    assert found == {}, f"make these public (with a docstring) or keep them in their module: {found}"
    planted = tmp_path / "planted.py"
    planted.write_text("from visualenv.spec.loader import _private\n")
    assert private_imports(planted) == ["visualenv.spec.loader._private"]


def test_render_imports_nothing_from_the_spec() -> None:
    """render/ reads its own plan (visualenv.render.plan), built by the compiler: never the spec's models."""
    edges = graph()
    found = sorted(
        f"{a} imports {b}"
        for a, targets in edges.items()
        if a.split(".")[:2] == ["visualenv", "render"]
        for b in targets
        if b.split(".")[:2] == ["visualenv", "spec"]
    )
    assert found == [], "\n".join(found)


def test_the_render_plan_has_no_field_of_type_any() -> None:
    """Every field of every dataclass in render/plan.py (RenderPlan among them) names its type."""
    import dataclasses
    import typing

    from visualenv.render import plan

    def holds_any(hint: object) -> bool:
        return hint is typing.Any or any(holds_any(arg) for arg in typing.get_args(hint))

    classes = [
        c
        for c in vars(plan).values()
        if isinstance(c, type) and dataclasses.is_dataclass(c) and c.__module__ == plan.__name__
    ]
    assert plan.RenderPlan in classes and len(classes) > 10
    untyped = [
        f"{c.__name__}.{f.name}"
        for c in classes
        for f in dataclasses.fields(c)
        if holds_any(typing.get_type_hints(c)[f.name])
    ]
    assert untyped == []
