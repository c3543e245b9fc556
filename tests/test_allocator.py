"""A batch of large images keeps the memory its render calls free (glibc): a large block freed and asked for again is
not faulted in; a batch of small images leaves the allocator as it is."""

from __future__ import annotations

import platform
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("bpy")

#: in a fresh process: the page faults of writing a fresh 64 MB block, before and after a batch of large images is made
CHILD = """
import ctypes
import resource

libc = ctypes.CDLL(None)
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]

def faults_of_a_fresh_block():
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    block = libc.malloc(64 * 2**20)
    ctypes.memset(block, 1, 64 * 2**20)  # written: every page faulted in, unless the heap holds it already
    libc.free(block)
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before

faults_of_a_fresh_block()
plain = faults_of_a_fresh_block()
from visualenv.env.batched import BatchedVectorEnv
from visualenv.render.blender import allocator
small = BatchedVectorEnv("specs/visual_cartpole.yaml", 2)  # 200 x 100 pixels a call: glibc reuses its blocks anyway
small.renderer
assert allocator._applied is None, "a small batch asked for it"
env = BatchedVectorEnv("specs/visual_cartpole.yaml", 128)  # 1.28 megapixels a call
env.renderer  # built (not rendered)
faults_of_a_fresh_block()  # the heap grows once
kept = faults_of_a_fresh_block()
env.close()
small.close()
print("FAULTS", allocator._applied, plain, kept)
"""


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_a_batch_reuses_freed_blocks_instead_of_faulting_them_in():
    out = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=300, cwd=Path(__file__).parents[1])
    line = next((ln for ln in out.stdout.splitlines() if ln.startswith("FAULTS")), None)
    assert line is not None, out.stderr[-2000:]
    _, applied, plain, kept = line.split()
    if int(plain) < 4000:
        pytest.skip(f"a fresh 64 MB block took only {plain} page faults here (huge pages): nothing to compare")
    assert applied == "True"
    assert int(kept) < int(plain) // 8, (plain, kept)  # about 16,000 faults of 4 KB pages before, a handful after
