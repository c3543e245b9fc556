"""A script that ends with envs still open exits quietly: nothing on stderr (no EGL or other native noise).

A batch left open used to print ``EGL Error (0x3009): EGL_BAD_MATCH`` three times
when Python exited (Blender freed its scene after its GPU context was gone);
open renderers now close at exit, before Blender tears down
(:mod:`visualenv.render.blender.runtime.at_exit`). Run in a subprocess: the noise came
after the interpreter's own shutdown began.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.blender

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = textwrap.dedent("""\
    import sys
    import visualenv

    if __name__ == "__main__":
        spec = sys.argv[1]
        batch = visualenv.make_vec(spec, 2, batched=True)
        batch.reset(seed=0)
        single = visualenv.make(spec)
        single.reset(seed=0)
        workers = visualenv.make_vec(spec, 2, batched=True, workers=2)  # a batch of one env in each of two processes
        workers.reset(seed=0)
        print("left open")
    """)


def test_a_script_that_leaves_envs_open_prints_nothing_on_stderr(tmp_path: Path) -> None:
    pytest.importorskip("bpy")
    script = tmp_path / "leave_open.py"
    script.write_text(SCRIPT, encoding="utf-8")
    done = subprocess.run(
        [sys.executable, str(script), str(ROOT / "specs" / "visual_cartpole.yaml")],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 0 and done.stdout.strip() == "left open", done.stdout + done.stderr
    assert done.stderr == ""
