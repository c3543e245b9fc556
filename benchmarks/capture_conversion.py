"""The in-memory readback's conversion (Cycles' float RGBA pass -> uint8 observation) per image size and thread count.

    python benchmarks/capture_conversion.py [THREADS ...]

Times `Capture.grayscale`, `.rgb` and `.raw` on a synthetic pass (values in 0..1.1,
so clamping is exercised) and checks that every thread count gives the same bytes.
Default threads: 1 and every core this process may use.
"""

import os
import sys
import time

import numpy as np

from visualenv.render.blender.capture import Capture


def per_call_ms(read, calls: int) -> float:
    read()
    start = time.perf_counter()
    for _ in range(calls):
        read()
    return (time.perf_counter() - start) / calls * 1000


threads = [int(t) for t in sys.argv[1:]] or sorted({1, len(os.sched_getaffinity(0))})
print(f"{'image':>11} {'threads':>7} {'grayscale ms':>13} {'rgb ms':>8} {'raw ms':>8} {'grayscale ns/px':>16}")
for side in (100, 400, 800, 1600, 2048):
    pass_values = np.random.default_rng(0).random(side * side * 4, dtype=np.float32) * np.float32(1.1)
    reference = None
    for count in threads:
        capture = Capture(threads=count).arm(side, side)
        capture._buffer[:] = pass_values
        capture._filled = True
        calls = max(3, 4_000_000 // (side * side))
        gray, rgb, raw = (per_call_ms(read, calls) for read in (capture.grayscale, capture.rgb, capture.raw))
        images = (capture.grayscale(), capture.rgb(), capture.raw())
        reference = reference or images
        assert all(np.array_equal(a, b) for a, b in zip(reference, images)), "thread counts must give the same bytes"
        capture.close()
        print(f"{side:>5}x{side:<5} {count:>7} {gray:>13.2f} {rgb:>8.2f} {raw:>8.2f} {gray * 1e6 / side ** 2:>16.1f}")
