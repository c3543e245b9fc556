"""The bundled MuJoCo ports read the MJCF files pinned in specs/mujoco/assets/, and no bundled spec warns.

The files are Gymnasium's (SOURCES.md names the version and each original's sha256): while that
Gymnasium is installed, the copies are its files byte for byte, and half_cheetah.xml, whose deprecated
``settotalmass`` is written out as inertials, compiles to Gymnasium's model bit for bit. Validating,
compiling and stepping every bundled spec emits no Python warning and writes nothing to stderr (where
MuJoCo and Blender print theirs).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import re
import subprocess
import sys
import warnings
from importlib import metadata
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mujoco")

from visualenv.compiler.program import compile_spec  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.files import package_file  # noqa: E402
from visualenv.spec.loader import load_spec  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
ASSETS = ROOT / "specs" / "mujoco" / "assets"
PORTS = sorted((ROOT / "specs" / "mujoco").glob("*.yaml"))
BUNDLED = sorted((ROOT / "specs").glob("*.yaml")) + PORTS + sorted((ROOT / "specs" / "dmc").glob("*.yaml"))


def vendoring() -> Any:
    """specs/mujoco/assets/vendor_gymnasium.py, the script that wrote the copies (its checks reused here)."""
    found = importlib.util.spec_from_file_location("vendor_gymnasium", ASSETS / "vendor_gymnasium.py")
    assert found is not None and found.loader is not None
    module = importlib.util.module_from_spec(found)
    found.loader.exec_module(module)
    return module


def sources() -> tuple[str, dict[str, str]]:
    """The Gymnasium version SOURCES.md names, and the sha256 of each original file."""
    text = (ASSETS / "SOURCES.md").read_text(encoding="utf-8")
    version = re.search(r"^Gymnasium (\S+) ", text, re.M)
    assert version is not None
    return version.group(1), dict(re.findall(r"^\| `([\w.]+)` \| `([0-9a-f]{64})` \|", text, re.M))


def test_the_ports_read_the_pinned_files_and_the_wheel_ships_them() -> None:
    for spec in PORTS:
        model = load_spec(spec).spec.physics.model
        assert model.startswith("assets/") and (spec.parent / model).is_file(), (spec.name, model)
    _, originals = sources()
    assert sorted(originals) == sorted(p.name for p in ASSETS.glob("*.xml"))
    assert "MIT License" in (ASSETS / "LICENSE.gymnasium").read_text(encoding="utf-8")
    package_data = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    assert all(f'"mujoco/assets/{pattern}"' in package_data for pattern in ("*.xml", "LICENSE.gymnasium", "SOURCES.md"))


def test_the_pinned_files_are_gymnasiums_own() -> None:
    version, originals = sources()
    if metadata.version("gymnasium") != version:
        pytest.skip(f"Gymnasium {metadata.version('gymnasium')} is installed; the copies are of {version}")
    vendor = vendoring()
    theirs = package_file("package:gymnasium.envs.mujoco/assets/reacher.xml").parent
    for name, sha in originals.items():
        original = (theirs / name).read_bytes()
        assert hashlib.sha256(original).hexdigest() == sha, name
        if name in vendor.VERBATIM:
            assert (ASSETS / name).read_bytes() == original, name
    cheetah = (ASSETS / vendor.EDITED).read_text(encoding="utf-8")
    compiler = re.search(r"<compiler [^>]*>", cheetah)
    assert compiler is not None and "settotalmass" not in compiler.group(0) and cheetah.count("<inertial ") == 7
    ours, gymnasiums = (
        vendor.compile_quietly(cheetah),
        vendor.compile_quietly((theirs / vendor.EDITED).read_text(encoding="utf-8")),
    )
    assert vendor.differences(ours, gymnasiums) == []
    heavier = vendor.compile_quietly(cheetah.replace('mass="6.25020920502092"', 'mass="6.250209205020921"'))
    assert "body_mass" in vendor.differences(heavier, gymnasiums)  # the control: the comparison sees one bit


@pytest.mark.parametrize("spec", BUNDLED, ids=[p.name for p in BUNDLED])
def test_compiling_and_stepping_a_bundled_spec_warns_nothing(spec: Path) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        compile_spec(load_spec(spec))  # a rendered spec's physics scene included
        env = VisualEnv(spec, render=False)
        env.reset(seed=0)
        env.step(env.action_space.sample())
        env.close()
    assert [str(w.message) for w in caught] == []


def test_validating_the_bundled_specs_prints_nothing_on_stderr() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "visualenv.cli", "validate", *map(str, BUNDLED)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 0 and done.stdout.count(": ok") == len(BUNDLED), done.stdout + done.stderr
    assert done.stderr == ""


@pytest.mark.blender
def test_building_half_cheetah_prints_nothing_on_stderr(tmp_path: Path) -> None:
    """The port that used to print MuJoCo's settotalmass deprecation: its build, rendered by Blender, prints no warning."""
    pytest.importorskip("bpy")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "visualenv.cli",
            "build",
            str(ROOT / "specs" / "mujoco" / "half_cheetah.yaml"),
            "-o",
            str(tmp_path),
            "--quiet",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 0 and "built VisualHalfCheetah-v0" in done.stdout, done.stdout + done.stderr
    assert done.stderr == "" and "warning" not in done.stdout.lower()
