"""A corpus of malformed specs, each run through the CLI with its expected messages.

Every file in ``tests/bad_specs/`` records what the CLI must print for it, in
header comments::

    # command: build                         (optional; default: validate)
    # expect: :14:9: unknown name 'thta'      (one line per problem, in order)

``:14:9:`` is the location after the file name (``:`` alone: no position) and
the rest is a substring of the message. Files that cannot hold a comment
(an empty file, bytes that are not UTF-8) are listed in ``expected.yaml``.

For each spec the CLI must exit with status 2, print exactly one line per
problem, each starting ``<file>:<line>:<col>:``, and never a traceback; what
Blender itself printed may follow, each line marked ``blender:``.
Specs marked ``build`` need Blender (``.blend`` files, textures, meshes and
object names in a scene file are checked when the scene is built); they are
skipped when the Blender renderer cannot be imported.
"""

from __future__ import annotations

import hashlib
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from visualenv.cli import main

CORPUS = Path(__file__).resolve().parents[1] / "bad_specs"
EXPECT = re.compile(r"^# expect: (:(?:\d+:(?:\d+:)?)?) (.+)$")


def _blender_available() -> bool:
    """Whether bpy is installed. Only its absence skips the build cases: with bpy there, a renderer that fails
    to import is a failure of these tests, not a reason to skip them."""
    try:
        import bpy  # noqa: F401
    except ImportError:
        return False
    return True


BLENDER = _blender_available()
needs_blender = pytest.mark.skipif(not BLENDER, reason="bpy is not installed")


@dataclass(frozen=True)
class Case:
    path: Path
    command: str
    expected: tuple[tuple[str, str], ...]  # (location, message substring)


def _cases() -> list[Case]:
    table = yaml.safe_load((CORPUS / "expected.yaml").read_text(encoding="utf-8"))
    cases = []
    for path in sorted(CORPUS.iterdir()):
        if path.suffix not in (".yaml", ".toml") or path.name == "expected.yaml":
            continue
        if path.name in table:
            entry = table[path.name]
            expected = tuple((e["at"], e["message"]) for e in entry["expect"])
            cases.append(Case(path, entry.get("command", "validate"), expected))
            continue
        header = []
        command = "validate"
        for line in path.read_text(encoding="utf-8").splitlines():
            if not line.startswith("#"):
                break
            if line.startswith("# command:"):
                command = line.split(":", 1)[1].strip()
            m = EXPECT.match(line)
            if m:
                header.append((m.group(1), m.group(2)))
        assert header, f"{path.name}: no '# expect:' header and no entry in expected.yaml"
        cases.append(Case(path, command, tuple(header)))
    return cases


CASES = _cases()


def _param(case: Case):
    marks = [needs_blender, pytest.mark.blender] if case.command == "build" else []
    return pytest.param(case, id=case.path.name, marks=marks)


def test_corpus_is_large_and_varied():
    assert len(CASES) >= 45
    assert sum(c.path.suffix == ".toml" for c in CASES) >= 5
    assert sum(c.command == "build" for c in CASES) >= 5


@pytest.fixture(scope="session")
def blend_scene(tmp_path_factory) -> Path:
    """A real .blend (objects Box, Cam, Sun), made by building a small valid spec."""
    if not BLENDER:
        pytest.skip("the Blender renderer does not import")
    folder = tmp_path_factory.mktemp("scene")
    spec = folder / "scene.yaml"
    spec.write_text(VALID_SCENE_SPEC.format(id="SceneForBadSpecs-v0"))
    result = CliRunner().invoke(main, ["build", str(spec), "--out", str(folder / "build"), "--quiet"])
    assert result.exit_code == 0, result.output
    return folder / "build" / "SceneForBadSpecs-v0" / "scene.blend"


VALID_SCENE_SPEC = """\
id: {id}
scene:
  objects:
    Box: {{primitive: cube}}
    Cam: {{camera: perspective, location: [0, -5, 0], look_at: [0, 0, 0]}}
    Sun: {{light: sun}}
state:
  x: {{init: 0}}
actions:
  discrete:
    - {{u: -1}}
    - {{u: 1}}
dynamics:
  update: {{x: x + u}}
actors:
  Box: {{location: [x, 0, 0]}}
observation: {{camera: Cam, resolution: [8, 8]}}
render: {{engine: cycles, preset: fast, view: {{resolution: [16, 16], preset: fast}}}}
"""


def run_case(case: Case, tmp_path: Path, request: pytest.FixtureRequest) -> tuple[Path, object]:
    """Run the CLI on `case` (build cases on a copy beside the assets, building into tmp_path)."""
    runner = CliRunner()
    if case.command == "build":
        blend = request.getfixturevalue("blend_scene")
        shutil.copytree(CORPUS / "assets", tmp_path / "assets")
        shutil.copy(blend, tmp_path / "assets" / "scene.blend")
        spec = tmp_path / case.path.name
        shutil.copy(case.path, spec)
        result = runner.invoke(main, ["build", str(spec), "--out", str(tmp_path / "build"), "--quiet"])
    else:
        spec = case.path
        result = runner.invoke(main, ["validate", str(spec)])
    return spec, result


@pytest.mark.parametrize("case", [_param(c) for c in CASES])
def test_bad_spec_is_reported(case: Case, tmp_path: Path, request: pytest.FixtureRequest):
    spec, result = run_case(case, tmp_path, request)
    output = result.output
    assert "Traceback" not in output, output
    assert result.exit_code == 2, f"exit code {result.exit_code}, output:\n{output}\nexception: {result.exception!r}"
    all_lines = output.splitlines()
    lines = [line for line in all_lines if not line.startswith("blender: ")]
    assert all_lines[: len(lines)] == lines, f"Blender's own lines must follow the errors:\n{output}"
    assert len(lines) == len(case.expected), f"expected {len(case.expected)} line(s), got:\n{output}"
    for line, (at, message) in zip(lines, case.expected):
        assert line.startswith(f"{spec}{at} "), f"expected location {at!r} in:\n{line}"
        assert message in line, f"expected {message!r} in:\n{line}"
    if case.command == "build":
        assert not (tmp_path / "build" / "Bad-v0").exists(), "a failed build must not leave a build folder"


def test_nothing_in_the_corpus_ran(tmp_path: Path):
    """The escape attempts in the corpus (Python tags, __import__, open) must leave no file behind."""
    for case in CASES:
        if case.command == "validate":
            CliRunner().invoke(main, ["validate", str(case.path)])
    assert not (CORPUS / "pwned.txt").exists()
    assert not Path("pwned.txt").exists()


def test_missing_spec_file_is_reported_without_traceback(tmp_path: Path):
    missing = tmp_path / "nope.yaml"
    result = CliRunner().invoke(main, ["validate", str(missing)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert result.output == f"{missing}: file not found\n"


def test_all_problems_of_several_files_are_listed(tmp_path: Path):
    files = [CORPUS / "expr_unknown_name.yaml", CORPUS / "resolution_negative.yaml"]
    result = CliRunner().invoke(main, ["validate", *map(str, files)])
    assert result.exit_code == 2
    assert len(result.output.splitlines()) == 3
    assert all(line.startswith(tuple(map(str, files))) for line in result.output.splitlines())


def _tree_digest(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@needs_blender
@pytest.mark.blender
def test_failed_build_keeps_the_earlier_build(tmp_path: Path):
    spec = tmp_path / "env.yaml"
    spec.write_text(VALID_SCENE_SPEC.format(id="KeepMe-v0"))
    out = tmp_path / "build"
    first = CliRunner().invoke(main, ["build", str(spec), "--out", str(out), "--quiet"])
    assert first.exit_code == 0, first.output
    folder = out / "KeepMe-v0"
    before = _tree_digest(folder)
    assert {"env.json", "scene.blend", "preview.png"} <= set(before)

    # same id, but a texture file is missing: the spec compiles, the scene build fails
    broken = "Box: {primitive: cube, material: {texture: {type: image, image: gone.png}}}"
    spec.write_text(VALID_SCENE_SPEC.format(id="KeepMe-v0").replace("Box: {primitive: cube}", broken))
    second = CliRunner().invoke(main, ["build", str(spec), "--out", str(out), "--quiet"])
    assert second.exit_code == 2 and "Traceback" not in second.output
    assert "image file not found" in second.output
    assert _tree_digest(folder) == before
    assert sorted(p.name for p in out.iterdir()) == ["KeepMe-v0"], "no temporary or .old folder may be left"


@needs_blender
@pytest.mark.blender
def test_blender_prints_nothing_when_a_mesh_imports(tmp_path: Path, capfd: pytest.CaptureFixture[str]):
    """The OBJ importer's timing lines are dropped when the build succeeds; only the CLI's own output is shown."""
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    spec = tmp_path / "env.yaml"
    spec.write_text(
        VALID_SCENE_SPEC.format(id="MeshQuiet-v0").replace("Box: {primitive: cube}", "Box: {mesh: tri.obj}")
    )
    capfd.readouterr()
    result = CliRunner().invoke(main, ["build", str(spec), "-o", str(tmp_path / "build"), "--quiet"])
    assert result.exit_code == 0, result.output
    printed = capfd.readouterr()
    assert "obj" not in (printed.out + printed.err).lower(), printed
