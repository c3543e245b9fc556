"""In-memory readback for Cycles: the Combined pass copied to numpy while Cycles still holds it.

Blender's background mode gives Python no access to a finished render: the
'Render Result' image has no pixels and the compositor's Viewer node is never
run. The portable route (see :mod:`readback`) writes a file and reads it back,
which costs about as much as the render itself at 100x100 (``visualenv bench --readback file``
against the default; results/benchmarks/single-env-vm.md).

A render engine, however, can read its own result while it renders. This
module wraps Cycles' ``RenderEngine.render`` (:func:`~visualenv.compat.blender.wrap_cycles_render`) so that, when a renderer has armed
a :class:`Capture`, the engine's Combined pass (linear, scene-referred RGBA) is
copied with ``foreach_get`` before Blender moves on (its conversion's cost per size and thread count:
``benchmarks/capture_conversion.py``). The wrapper
is installed once per process and does nothing for renders nobody armed.

The readers (:meth:`Capture.rgb`, :meth:`Capture.grayscale`, :meth:`Capture.raw`)
then apply what Blender's 'Standard' (or 'Raw') view transform and 8-bit output
would: the sRGB transfer function and round-half-up quantisation.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable

import numpy as np

from visualenv.compat.blender import wrap_cycles_render
from visualenv.errors import RenderError
from visualenv.render.pixels import LUMA_601

#: a band of at least this many pixels per thread: below it, starting threads costs more than they save
PIXELS_PER_THREAD = 256 * 256

_armed: Capture | None = None
_installed: bool | None = None


def install() -> bool:
    """Have Cycles' render method copy the armed capture's pass, once; False when Cycles is not available in this Blender."""
    global _installed
    if _installed is None:
        _installed = wrap_cycles_render(_copy_to_armed)
    return _installed


def _copy_to_armed(engine: Any) -> None:
    """At the end of each Cycles render: the Combined pass into the capture a renderer armed, if any."""
    if _armed is not None:
        _armed._copy_from(engine.get_result())


class Capture:
    """Armed around one render call: ``with capture: render()``, then one of the readers.

    The readers convert the copied pass to the observation's uint8 layout
    (top row first, C-contiguous) in scratch buffers kept between frames, so a
    step allocates only its result. A large image (a batch's tiles) is converted
    in bands of rows on several threads: numpy's loops release the GIL, and the
    conversion is per pixel, so the bytes are the same as in one pass.
    """

    def __init__(self, threads: int | None = None) -> None:
        self._buffer = np.empty(0, dtype=np.float32)  # Combined pass: RGBA rows, bottom row first
        self._scaled = np.empty(0, dtype=np.float32)  # scratch: the pass scaled and clamped
        self._levels = np.empty(0, dtype=np.uint16)  # scratch: the same as integer levels
        self._shape = (0, 0)
        self._filled = False
        self._threads = max(1, threads if threads is not None else len(os.sched_getaffinity(0)))
        self._pool: ThreadPoolExecutor | None = None

    def arm(self, width: int, height: int) -> Capture:
        size = width * height * 4
        if self._buffer.size != size:
            self._buffer = np.empty(size, dtype=np.float32)
            self._scaled = np.empty(size, dtype=np.float32)
            self._levels = np.empty(size, dtype=np.uint16)
        self._shape = (height, width)
        return self

    def __enter__(self) -> Capture:
        global _armed
        self._filled = False
        _armed = self
        return self

    def __exit__(self, *exc: object) -> None:
        global _armed
        _armed = None

    def _copy_from(self, result: Any) -> None:
        if result is None or not result.layers:
            return
        combined = result.layers[0].passes.get("Combined")
        if combined is None or len(combined.rect) * 4 != self._buffer.size:
            return
        combined.rect.foreach_get(self._buffer)
        self._filled = True

    def _check_filled(self) -> None:
        if not self._filled:
            raise RenderError("Cycles finished without a Combined pass to read (was the render cancelled?)")

    def _quantised(self, top: int, rows: slice) -> np.ndarray:
        """(rows, W, 4) levels 0..top of those rows of the pass (bottom row first): ``linear * top`` rounded half up and clamped.

        Ufuncs with ``out=`` on the contiguous pass: numpy 1.x's ``np.clip`` with
        scalar bounds, fresh arrays and a flipped (negative-stride) input each
        cost more than the arithmetic itself. NaN becomes level 0 (``np.fmax``):
        cast to an integer, its level would be whatever the CPU's conversion
        instruction makes of it (0 with SSE's, 65535 with AVX-512's unsigned one).
        """
        width = self._shape[1]
        band = slice(rows.start * width * 4, rows.stop * width * 4)
        scaled = self._scaled[band]
        np.multiply(self._buffer[band], np.float32(top), out=scaled)
        np.add(scaled, np.float32(0.5), out=scaled)
        np.minimum(scaled, np.float32(top), out=scaled)
        np.fmax(scaled, np.float32(0.0), out=scaled)  # NaN too
        levels = self._levels[band]
        levels[...] = scaled  # truncates: with the + 0.5, rounds half up
        return levels.reshape(rows.stop - rows.start, width, 4)

    def _convert(self, channels: int, rows_to_bytes: Callable[[slice], np.ndarray]) -> np.ndarray:
        """(H, W, channels) top row first: `rows_to_bytes` of bands of rows (bottom first), flipped into place."""
        self._check_filled()
        height, width = self._shape
        out = np.empty((height, width, channels), dtype=np.uint8)

        def band(rows: slice) -> None:
            out[height - rows.stop : height - rows.start] = rows_to_bytes(rows)[::-1]

        bands = min(self._threads, height, max(1, height * width // PIXELS_PER_THREAD))
        if bands == 1:
            band(slice(0, height))
        else:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(self._threads, thread_name_prefix="visualenv-capture")
            edges = np.linspace(0, height, bands + 1).astype(int)
            list(self._pool.map(band, [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]))
        return out

    def rgb(self, raw: bool = False) -> np.ndarray:
        """(H, W, 3) sRGB bytes, as Blender's 'Standard' view transform writes them (`raw`: the linear values, as 'Raw' does)."""
        if raw:
            return self._convert(3, lambda rows: self._quantised(255, rows)[:, :, :3].astype(np.uint8))
        return self._convert(3, lambda rows: np.take(SRGB_TABLE, self._quantised(65535, rows)[:, :, :3]))

    def grayscale(self, raw: bool = False) -> np.ndarray:
        """(H, W, 1) BT.601 luma of the sRGB bytes (`raw`: of the 'Raw' bytes): the same bytes as ``to_grayscale(rgb(raw))``, in one pass."""
        top, tables = (255, LUMA_RAW_TABLES) if raw else (65535, LUMA_TABLES)

        def rows_to_bytes(rows: slice) -> np.ndarray:
            levels = self._quantised(top, rows)
            luma = np.take(tables[0], levels[:, :, 0])
            luma += np.take(tables[1], levels[:, :, 1])
            luma += np.take(tables[2], levels[:, :, 2])
            luma *= np.float32(0.001)
            return luma.astype(np.uint8)[:, :, None]

        return self._convert(1, rows_to_bytes)

    def linear(self) -> np.ndarray:
        """(H, W, 4) a copy of the linear Combined pass, top row first: every bit the 8-bit readers round away."""
        self._check_filled()
        height, width = self._shape
        return self._buffer.reshape(height, width, 4)[::-1].copy()

    def raw(self) -> np.ndarray:
        """(H, W, 1) the red channel's linear values as bytes (Blender's 'Raw' view: used for depth)."""
        return self._convert(1, lambda rows: self._quantised(255, rows)[:, :, :1].astype(np.uint8))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def _srgb_table(size: int = 65536) -> np.ndarray:
    x = np.linspace(0.0, 1.0, size, dtype=np.float64)
    encoded = np.where(x <= 0.0031308, x * 12.92, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.floor(encoded * 255.0 + 0.5).astype(np.uint8)


#: sRGB bytes for linear values quantised to 16 bits: a table lookup is faster than evaluating
#: the power function per pixel (``visualenv bench``'s time outside the render call shows the
#: conversion), and agrees with it except at exact rounding ties
SRGB_TABLE = _srgb_table()


def _luma_tables(encoded: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per channel, the byte `encoded` gives each level (sRGB, or raw) times its BT.601 weight (float32, exact), the red one plus 500.5.

    Summed and scaled by 0.001, then truncated, they give ``(299 R + 587 G + 114 B + 500) // 1000``
    exactly: the sum is an integer plus 0.5, at least 0.0005 from the next integer after scaling,
    far beyond float32's rounding error at these magnitudes.
    """
    tables = [encoded.astype(np.float32) * np.float32(weight) for weight in LUMA_601]
    tables[0] += np.float32(500.5)
    return tables[0], tables[1], tables[2]


#: the BT.601 luma tables :meth:`Capture.grayscale` sums (:func:`_luma_tables`)
LUMA_TABLES = _luma_tables(SRGB_TABLE)
#: the same for 'Raw' bytes (physics.look 'mujoco'), indexed by the byte itself
LUMA_RAW_TABLES = _luma_tables(np.arange(256))
