"""What holds on a machine without the optional parts: visualenv imports without Ray, and the suite collects without bpy.

A test module that imports the Blender backend at its top fails at collection where bpy
is absent, and takes the whole run down with it; those modules skip instead.
"""

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_import_visualenv_never_imports_ray():
    code = "import sys, visualenv, visualenv.cli, visualenv.train.sb3, visualenv.train.play; assert 'ray' not in sys.modules, 'ray imported'"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert result.returncode == 0, result.stderr


def test_the_suite_collects_without_bpy(tmp_path):
    """With `import bpy` failing (as on a machine without it), every test module collects: none errors."""
    (tmp_path / "sitecustomize.py").write_text(
        "import sys\nsys.modules['bpy'] = None  # `import bpy` raises ImportError\n"
    )
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider", str(REPO / "tests")],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(tmp_path)},
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "could not import 'bpy'" in result.stdout  # the Blender-only modules skipped, so bpy really was missing
    assert " error" not in result.stdout.splitlines()[-1], result.stdout[-2000:]
