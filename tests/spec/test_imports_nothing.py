"""A spec is data: the files it names are read, never imported or run.

``package:`` model paths are found on disk. The package here is written by the test;
importing it (its top-level ``__init__`` or the subpackage's) writes a marker file.
Validating, compiling, making, stepping and building a spec that names ``package:`` of it
must write nothing; importing it, as the control, does. MJCF ``include`` and ``file``
attributes are files MuJoCo reads (XML, meshes, images): naming a Python file there is an
error, never an import.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip("mujoco")

from visualenv.cli import main  # noqa: E402
from visualenv.compiler.program import compile_spec  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.errors import SpecError  # noqa: E402
from visualenv.files import package_file  # noqa: E402
from visualenv.spec.loader import load_spec  # noqa: E402

#: a hinged pole with a motor, a camera that looks at it and a light
MODEL = """\
<mujoco model="pole">
  <option timestep="0.01"/>
  <worldbody>
    <light name="sun" directional="true" pos="0 0 3" dir="0 0 -1"/>
    <camera name="front" pos="0 -2 0.5" xyaxes="1 0 0 0 0 1"/>
    <body name="pole" pos="0 0 0.5">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom name="rod" type="capsule" fromto="0 0 0 0 0 0.5" size="0.05" rgba="0 0.7 0.7 1"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="torque" joint="hinge" ctrllimited="true" ctrlrange="-1 1"/>
  </actuator>
</mujoco>
"""

SPEC = """\
id: PackagedPole-v0
physics:
  model: {model}
reward: -qpos_hinge * qpos_hinge
observation: {{camera: front, resolution: [16, 16], color: rgb}}
max_steps: 5
"""


@pytest.fixture
def hostile_package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[str, Path]:
    """A package `sidefx_<n>` on sys.path whose import (top level or its `models` subpackage) writes a marker file."""
    name = f"sidefx_{tmp_path.name.replace('-', '_')}"
    marker = tmp_path / "imported.txt"
    root = tmp_path / "site" / name
    (root / "models").mkdir(parents=True)
    for init in (root / "__init__.py", root / "models" / "__init__.py"):
        init.write_text(
            f"import pathlib\npathlib.Path({str(marker)!r}).open('a').write({str(init)!r} + '\\n')\n", encoding="utf-8"
        )
    (root / "models" / "pole.xml").write_text(MODEL, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    importlib.invalidate_caches()
    yield name, marker
    for module in [m for m in sys.modules if m == name or m.startswith(name + ".")]:
        del sys.modules[module]


def write_spec(folder: Path, model: str) -> Path:
    path = folder / "spec.yaml"
    path.write_text(SPEC.format(model=model), encoding="utf-8")
    return path


def test_a_package_path_is_validated_made_and_stepped_without_importing_the_package(
    tmp_path: Path, hostile_package
) -> None:
    name, marker = hostile_package
    spec = write_spec(tmp_path, f"package:{name}.models/pole.xml")
    result = CliRunner().invoke(main, ["validate", str(spec)])
    assert result.exit_code == 0 and "ok" in result.output, result.output
    program = compile_spec(load_spec(spec))
    assert (
        program.physics is not None and program.physics.model.path == tmp_path / "site" / name / "models" / "pole.xml"
    )
    env = VisualEnv(spec, render=False)
    env.reset(seed=0)
    for _ in range(5):
        obs, reward, _, _, _ = env.step(np.array([1.0]))
    assert env.unwrapped.data.qpos[0] != 0 and np.isfinite(obs).all()
    env.close()
    assert not marker.exists(), marker.read_text()
    assert name not in sys.modules
    importlib.import_module(f"{name}.models")  # the control: importing it does write the marker
    assert marker.read_text().count("__init__.py") == 2


def test_a_namespace_package_is_searched_in_every_folder_it_spans(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    name = f"nspkg_{tmp_path.name.replace('-', '_')}"
    for portion in ("one", "two"):
        (tmp_path / portion / name / "models").mkdir(parents=True)
        monkeypatch.syspath_prepend(str(tmp_path / portion))
    (tmp_path / "one" / name / "models" / "pole.xml").write_text(MODEL, encoding="utf-8")
    importlib.invalidate_caches()
    assert package_file(f"package:{name}.models/pole.xml") == tmp_path / "one" / name / "models" / "pole.xml"
    assert name not in sys.modules


@pytest.mark.parametrize(
    "model, expected",
    [
        ("package:no_such_package_xyz/pole.xml", "no installed package 'no_such_package_xyz'"),
        ("package:{name}.nothing/pole.xml", "no installed package '{name}.nothing'"),
        ("package:{name}.models/missing.xml", "no MJCF file"),
        ("package:{name}.models", "expected package:<package>/<path inside it>"),
        ("package:../{name}/pole.xml", "expected package:<package>/<path inside it>"),
        ("package:textwrap/pole.xml", "no installed package 'textwrap'"),  # a module, not a package
    ],
)
def test_an_unknown_package_or_file_is_a_located_error(
    tmp_path: Path, hostile_package, model: str, expected: str
) -> None:
    name, marker = hostile_package
    spec = write_spec(tmp_path, model.format(name=name))
    with pytest.raises(SpecError) as caught:
        compile_spec(load_spec(spec))
    message = str(caught.value)
    assert "spec.yaml:3" in message and "physics.model" in message and expected.format(name=name) in message, message
    assert not marker.exists()


@pytest.mark.blender
def test_build_renders_a_package_model_without_importing_the_package(tmp_path: Path, hostile_package) -> None:
    pytest.importorskip("bpy")
    name, marker = hostile_package
    spec = write_spec(tmp_path, f"package:{name}.models/pole.xml")
    result = CliRunner().invoke(main, ["build", str(spec), "-o", str(tmp_path / "build"), "--quiet"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "build" / "PackagedPole-v0" / "preview.png").is_file()
    assert not marker.exists() and name not in sys.modules


@pytest.mark.parametrize(
    "element, expected",
    [
        ('<include file="__init__.py"/>', "Include error: 'XML parse error"),
        ('<asset><mesh name="m" file="__init__.py"/></asset>', "no decoder found for mesh file"),
        ('<asset><texture name="t" type="2d" file="__init__.py"/></asset>', "Element name 't'"),
    ],
)
def test_mjcf_include_and_file_attributes_are_files_mujoco_reads(
    tmp_path: Path, hostile_package, element: str, expected: str
) -> None:
    name, marker = hostile_package
    folder = tmp_path / "site" / name / "models"
    (folder / "pole.xml").write_text(MODEL.replace('<option timestep="0.01"/>', element), encoding="utf-8")
    with pytest.raises(SpecError) as caught:
        compile_spec(load_spec(write_spec(tmp_path, f"package:{name}.models/pole.xml")))
    message = str(caught.value)
    assert "physics.model" in message and "MuJoCo cannot load" in message and expected in message, message
    assert not marker.exists() and name not in sys.modules
