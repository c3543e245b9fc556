"""glibc's allocator (visualenv/compat/glibc.py): the policy does what it says where it is applied (visualenv's commands
and workers, or GLIBC_TUNABLES), and nothing else changes a process's allocator: after a large batch is made, stepped
and closed, a freed 64 MB array goes back to the system as in a plain process.

Each measurement runs in a fresh process: the policy, once applied, is the whole process's."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from visualenv.compat import glibc

ROOT = Path(__file__).parents[2]
pytestmark = pytest.mark.skipif(glibc.version() is None, reason="glibc's allocator: this C library is another")

#: how much of a freed 64 MB array went back to the system, in MB (psutil's resident set)
RETURNED = """
import numpy as np, psutil

def returned_mb():
    block = np.ones(64 * 2**20, np.uint8)  # written: every page resident
    held = psutil.Process().memory_info().rss
    del block
    return (held - psutil.Process().memory_info().rss) / 2**20
"""
#: a freed 64 MB array counts as returned above this, and as kept below KEPT_BELOW
RETURNED_ABOVE, KEPT_BELOW = 56, 8


def run(code: str, env: dict[str, str] | None = None, timeout: int = 300) -> dict[str, float]:
    """Run `code` (after RETURNED) in a fresh interpreter; the `name value` pairs of its lines that start with FIGURE."""
    environment = {k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"}
    out = subprocess.run(
        [sys.executable, "-c", RETURNED + code],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
        env={**environment, **(env or {})},
    )
    assert out.returncode == 0, out.stderr[-3000:]
    figures = {}
    for line in out.stdout.splitlines():
        if line.startswith("FIGURE "):
            _, name, value = line.split()
            figures[name] = float(value)
    return figures


def test_the_glibc_here_is_one_the_policy_was_written_for():
    """Fails when glibc moves: older than the tunables the docs name, or without mallopt and malloc_trim."""
    assert glibc.version() >= glibc.OLDEST, (
        f"glibc {glibc.version()}: compat/glibc.py was written for {glibc.OLDEST} and later"
    )
    assert glibc.available(), "mallopt or malloc_trim is missing from this glibc"


def test_the_policy_keeps_freed_memory_and_a_plain_process_returns_it():
    figures = run("""
from visualenv.compat import glibc
print("FIGURE plain", returned_mb())
print("FIGURE applied", int(glibc.apply_policy()))
returned_mb()  # the heap grows once
print("FIGURE kept", returned_mb())
""")
    assert figures["plain"] > RETURNED_ABOVE and figures["applied"] == 1, figures
    assert figures["kept"] < KEPT_BELOW, figures


def test_the_documented_tunables_are_the_same_policy_and_win_over_it():
    """GLIBC_TUNABLES (what docs/performance.md gives for your own process) keeps freed memory too; a process started
    with malloc tunables of its own keeps them: apply_policy then changes nothing."""
    figures = run(
        """
from visualenv.compat import glibc
returned_mb()
print("FIGURE kept", returned_mb())
print("FIGURE applied", int(glibc.apply_policy()))
""",
        env={"GLIBC_TUNABLES": glibc.POLICY_TUNABLES},
    )
    assert figures["kept"] < KEPT_BELOW and figures["applied"] == 0, figures


def test_a_command_applies_the_policy():
    figures = run("""
from click.testing import CliRunner
from visualenv.cli import main
print("FIGURE before", returned_mb())
assert CliRunner().invoke(main, ["schema"]).exit_code == 0
returned_mb()
print("FIGURE after", returned_mb())
""")
    assert figures["before"] > RETURNED_ABOVE and figures["after"] < KEPT_BELOW, figures


WORKERS = (
    RETURNED
    + """
import gymnasium as gym
import visualenv


class Probe(gym.Wrapper):
    def returned_mb(self):
        returned_mb()
        return returned_mb()


if __name__ == "__main__":
    vec = visualenv.make_vec("specs/visual_cartpole.yaml", 2, render=False, pin=False, wrapper_class=Probe)
    print("FIGURE workers", max(vec.call("returned_mb")))
    print("FIGURE parent", returned_mb())
    vec.close()
"""
)


def test_vector_env_workers_apply_the_policy_and_leave_the_parent_alone(tmp_path):
    script = tmp_path / "workers.py"  # a file: spawned workers import the wrapper class from it
    script.write_text(WORKERS)
    out = subprocess.run(
        [sys.executable, str(script)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
        env={k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"},
    )
    assert out.returncode == 0, out.stderr[-3000:]
    figures = dict(
        (line.split()[1], float(line.split()[2])) for line in out.stdout.splitlines() if line.startswith("FIGURE ")
    )
    assert figures["workers"] < KEPT_BELOW and figures["parent"] > RETURNED_ABOVE, figures


@pytest.mark.blender
def test_making_stepping_and_closing_envs_leaves_the_allocator_as_it_was():
    """A batch of 1.28 megapixels a render call (its buffers well past glibc's largest mmap threshold) and a single env
    with its view: while they step and once they are closed, a freed 64 MB array goes back to the system."""
    pytest.importorskip("bpy")
    figures = run(
        """
import numpy as np
import visualenv
from visualenv.env.batch import BatchedVectorEnv

print("FIGURE plain", returned_mb())
batch = BatchedVectorEnv("specs/visual_cartpole.yaml", 128)  # 128 images of 100 x 100 a call
batch.reset(seed=0)
for _ in range(2):
    batch.step(np.zeros(128, np.int64))
print("FIGURE stepping", returned_mb())
batch.close()
print("FIGURE closed", returned_mb())
env = visualenv.make("VisualCartPole-v0", render_mode="rgb_array")
env.reset(seed=0)
env.step(0)
env.render()
env.close()
print("FIGURE single", returned_mb())
""",
        timeout=600,
    )
    assert min(figures.values()) > RETURNED_ABOVE, figures
