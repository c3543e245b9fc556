"""The `blender` mark's check (tests/conftest.py): an unmarked test that imports bpy fails, even where a marked test
collected before it had imported bpy already (the unmarked tests run first)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

IMPORTS_BPY = """
import sys, types
import pytest

{mark}
def test_{name}():
    sys.modules.setdefault("bpy", types.ModuleType("bpy"))  # a stand-in: the check looks only at sys.modules
"""


def test_an_unmarked_test_that_imports_bpy_fails_though_a_marked_one_was_collected_first(tmp_path: Path) -> None:
    shutil.copy(Path(__file__).parent / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "pytest.ini").write_text("[pytest]\nmarkers =\n    blender: renders\n")
    (tmp_path / "test_a_marked.py").write_text(IMPORTS_BPY.format(mark="@pytest.mark.blender", name="marked"))
    (tmp_path / "test_b_unmarked.py").write_text(IMPORTS_BPY.format(mark="", name="unmarked"))
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tmp_path)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert run.returncode == 1, run.stdout
    assert "test_b_unmarked.py::test_unmarked imported bpy but is not marked blender" in run.stdout
    assert "1 failed, 1 passed" in run.stdout
