"""How a batch splits its renders into Cycles calls: how many envs one image holds (:func:`envs_per_call`), and how
many envs an autoreset just reset are rendered alone before all tiles again cost less (:func:`alone_limit`)."""

from __future__ import annotations

import math

from visualenv.render.blender.batch.tiles_camera import grid_shape

#: the largest image one render call makes; past it a batch is rendered in several calls: a larger image
#: comes back black from the in-memory readback (Cycles' result then reaches Blender in tiles, after the
#: engine's render returns; results/benchmarks/batched-cpu-vm.md); the file readback is unaffected
MAX_IMAGE_PIXELS = 2048 * 2048
#: what rendering a few envs alone costs beyond their own tiles, in tiles: switching the scene's camera to the
#: one-tile camera and back makes Cycles re-synchronise (results/benchmarks/code-choices.md)
ALONE_OVERHEAD_TILES = 16
#: reset envs rendered alone, at most, per square root of N (:func:`alone_limit`): Cycles on the CPU, times the
#: square root of its render threads; Cycles on a GPU
ALONE_PER_ROOT_CPU = 6.0
ALONE_PER_ROOT_GPU = 0.5
#: the widest and tallest image one render call makes (Cycles renders larger ones in several tiles of its own)
MAX_IMAGE_SIDE = 2048


def alone_limit(num_envs: int, device: str, threads: int) -> float:
    """How many reset envs a batch renders alone (one env-sized call each) before rendering all N tiles again is cheaper.

    One env alone is a render call over the whole scene, whose cost grows with N; the grid again costs N tiles, and a
    tile costs less the more threads trace it, and little on a GPU, so the break-even grows as the square root of N
    and falls with the threads (docs/performance.md, *Reset envs rendered alone*; the measured break-evens:
    results/benchmarks/batched-reset-alone.md). Below about 16 envs the camera switch (ALONE_OVERHEAD_TILES) decides.
    """
    per_root = ALONE_PER_ROOT_GPU if device == "GPU" else ALONE_PER_ROOT_CPU / math.sqrt(max(1, threads))
    return min(per_root * math.sqrt(num_envs), num_envs - ALONE_OVERHEAD_TILES)


def envs_per_call(count: int, width: int, height: int) -> int:
    """The most envs one render call takes: their grid's image must stay within MAX_IMAGE_PIXELS."""
    n = max(1, min(count, MAX_IMAGE_PIXELS // (width * height)))
    while n > 1 and math.prod(grid_shape(n)) * width * height > MAX_IMAGE_PIXELS:
        n -= 1
    return n
