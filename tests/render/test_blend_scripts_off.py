"""Scripts a .blend carries never run: `inspect`, `init`, `build` and an env stepping over the file write nothing.

tests/fixtures/scripted_blend.py writes a scene with a text block registered to run on load and a
driver with a Python expression, each of which writes a marker file when it runs. The control shows
that they do run in this bpy once "Auto Run Python Scripts" is on; visualenv turns it off when it
loads bpy and before every read, even in a process that had turned it on.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

pytest.importorskip("bpy")

from visualenv.cli import main  # noqa: E402

pytestmark = pytest.mark.blender

FIXTURE = Path(__file__).parents[1] / "fixtures" / "scripted_blend.py"
ROOT = Path(__file__).resolve().parents[2]

SPEC = """\
id: Scripted-v0
scene: {file: scripted.blend, world: {color: [0, 0, 0], strength: 0}}
state: {x: {init: 0.0}}
actions: {discrete: [{u: 0}, {u: 1}]}
dynamics: {update: {x: x + 0.5 * u}}
actors:
  Ball: {location: [x, 0, 0]}
observation: {camera: Cam, resolution: [24, 16], color: rgb}
render: {engine: cycles, preset: fast}
max_steps: 10
"""


@pytest.fixture(scope="module")
def scripted(tmp_path_factory) -> tuple[Path, Path]:
    """The folder holding scripted.blend and spec.yaml, and the marker prefix its scripts write to."""
    folder = tmp_path_factory.mktemp("scripted")
    marker = folder / "ran"
    subprocess.run(
        [sys.executable, str(FIXTURE), str(folder / "scripted.blend"), str(marker)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    (folder / "spec.yaml").write_text(SPEC, encoding="utf-8")
    return folder, marker


def markers(marker: Path) -> list[str]:
    return sorted(p.name for p in marker.parent.glob(marker.name + ".*"))


def run_python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )


def test_the_files_scripts_run_when_blender_is_allowed_to_run_them(scripted, tmp_path) -> None:
    """The control: with auto-run on, opening the file runs its text block and evaluating the scene its driver."""
    folder, _ = scripted
    marker = tmp_path / "ran"
    subprocess.run(
        [sys.executable, str(FIXTURE), str(tmp_path / "control.blend"), str(marker)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    assert markers(marker) == []  # saving it ran nothing
    out = run_python(f"""
        import bpy
        bpy.context.preferences.filepaths.use_scripts_auto_execute = True
        bpy.ops.wm.open_mainfile(filepath={str(tmp_path / "control.blend")!r}, use_scripts=True)
        bpy.context.scene.frame_set(2)
    """)
    assert out.returncode == 0, out.stderr
    assert markers(marker) == ["ran.driver", "ran.text"]


def test_inspect_init_and_build_run_none_of_the_files_scripts(scripted, tmp_path) -> None:
    folder, marker = scripted
    inspected = CliRunner().invoke(main, ["inspect", str(folder / "scripted.blend")])
    assert inspected.exit_code == 0 and "scene Scene: camera Cam" in inspected.output, inspected.output
    assert "rotation_euler (driver)" in inspected.output  # the driver is reported, not run
    started = CliRunner().invoke(main, ["init", str(folder / "scripted.blend"), "-o", str(tmp_path / "starter.yaml")])
    assert started.exit_code == 0, started.output
    built = CliRunner().invoke(main, ["build", str(folder / "spec.yaml"), "-o", str(tmp_path / "build"), "--quiet"])
    assert built.exit_code == 0, built.output
    assert (tmp_path / "build" / "Scripted-v0" / "preview.png").is_file()
    assert markers(marker) == []


def test_an_env_over_the_file_steps_without_running_its_scripts_even_where_autorun_was_on(scripted) -> None:
    """A process that turned auto-run on before importing visualenv, and again before making the env."""
    folder, marker = scripted
    out = run_python(f"""
        import bpy
        paths = bpy.context.preferences.filepaths
        paths.use_scripts_auto_execute = True
        import visualenv.render.blender
        print("after import:", paths.use_scripts_auto_execute)
        paths.use_scripts_auto_execute = True
        from visualenv.env.visual_env import VisualEnv
        env = VisualEnv({str(folder / "spec.yaml")!r})
        obs, _ = env.reset(seed=0)
        for _ in range(3):
            obs, *_ = env.step(1)
        print("after steps:", paths.use_scripts_auto_execute, int(obs.max()))
        env.close()
    """)
    assert out.returncode == 0, out.stderr
    assert "after import: False" in out.stdout and "after steps: False" in out.stdout, out.stdout
    assert int(out.stdout.split()[-1]) > 60  # the ball was rendered
    assert markers(marker) == []
