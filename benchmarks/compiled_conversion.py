"""The readback's grayscale conversion compiled into one pass (numba), against `Capture.grayscale` (numpy).

    pip install numba==0.60.0      # not a visualenv dependency: this script weighs the lever
    python benchmarks/compiled_conversion.py

One loop per pixel reads R, G, B, quantises each to 16-bit levels as numpy does (``v * 65535 + 0.5``, clamped, NaN
to 0), looks the sRGB byte up and sums BT.601's integer weights; rows are flipped as they are written. It checks that
the bytes equal numpy's (with NaN, negative and over-range values in the pass), then times both, and a plain copy of
the pass (what the VM's memory allows).
"""

import sys
import time
from functools import partial

import numpy as np

from visualenv.render.blender.capture import SRGB_TABLE, Capture

try:
    import numba
except ImportError:
    sys.exit("needs numba: pip install numba==0.60.0")


def make(parallel: bool):
    @numba.njit(parallel=parallel, nogil=True)
    def grayscale(buffer, height, width, srgb, out):
        for r in numba.prange(height):
            source = (height - 1 - r) * width * 4
            for c in range(width):
                i = source + c * 4
                luma = np.int32(500)
                for channel, weight in ((0, 299), (1, 587), (2, 114)):
                    v = buffer[i + channel] * np.float32(65535.0) + np.float32(0.5)
                    v = v if v > np.float32(0.0) else np.float32(0.0)  # NaN too
                    v = v if v < np.float32(65535.0) else np.float32(65535.0)
                    luma += np.int32(weight) * np.int32(srgb[np.int32(v)])
                out[r, c, 0] = np.uint8(luma // 1000)
    return grayscale


def ns_per_pixel(call, pixels: int) -> float:
    call()
    calls = max(3, 4_000_000 // pixels)
    start = time.perf_counter()
    for _ in range(calls):
        call()
    return (time.perf_counter() - start) / calls / pixels * 1e9


one_thread, threads = make(False), make(True)
print(f"{'image':>11} {'numpy ns/px':>12} {'compiled, 1 thread':>19} {'compiled, all':>14} {'copy of the pass':>17}")
for side in (100, 800, 2048):
    values = np.random.default_rng(0).random(side * side * 4, dtype=np.float32) * np.float32(1.1)
    values[::97], values[5::101] = np.nan, -0.3
    capture = Capture().arm(side, side)
    capture._buffer[:] = values
    capture._filled = True
    out = np.empty((side, side, 1), dtype=np.uint8)
    with np.errstate(invalid="ignore"):
        reference = capture.grayscale()
        for kernel in (one_thread, threads):
            kernel(capture._buffer, side, side, SRGB_TABLE, out)
            assert np.array_equal(out, reference), "the compiled conversion must give numpy's bytes"
        copy = np.empty_like(values)
        figures = [ns_per_pixel(capture.grayscale, side * side),
                   ns_per_pixel(partial(one_thread, capture._buffer, side, side, SRGB_TABLE, out), side * side),
                   ns_per_pixel(partial(threads, capture._buffer, side, side, SRGB_TABLE, out), side * side),
                   ns_per_pixel(partial(np.copyto, copy, values), side * side)]
    capture.close()
    print(f"{side:>5}x{side:<5} {figures[0]:>12.2f} {figures[1]:>19.2f} {figures[2]:>14.2f} {figures[3]:>17.2f}")
