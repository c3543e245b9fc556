"""Rendered pixels to numpy: an uncompressed BMP in shared memory.

Blender writes the render to a 24-bit BMP (``write_still``) in ``/dev/shm``
(a RAM disk; falls back to the temp dir), and :func:`read_bmp` views it with
numpy: bottom-up rows padded to 4 bytes, BGR order, flipped here so row 0 is
the top of the image. Each renderer owns one file, deleted on close or when
the renderer is garbage-collected (:class:`OutputFile`).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import sys
import tempfile
import weakref

import numpy as np

_counter = itertools.count()

#: ITU-R BT.601 luma weights (the same as OpenCV's and Pillow's "L" conversion), applied to sRGB bytes
LUMA_601 = (299, 587, 114)


def _shm_dir() -> str:
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


def _unlink(path: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


class OutputFile:
    """A unique BMP path for one renderer, removed on close() or garbage collection."""

    def __init__(self) -> None:
        self.path = os.path.join(_shm_dir(), f"visualenv-{os.getpid()}-{next(_counter)}-{id(self):x}.bmp")
        self._finalizer = weakref.finalize(self, _unlink, self.path)

    def close(self) -> None:
        self._finalizer()


def read_bmp(path: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB, top row first, from an uncompressed 24-bit BMP."""
    data = np.fromfile(path, dtype=np.uint8)
    header = data[:54].tobytes()
    if header[:2] != b"BM":
        raise OSError(f"{path} is not a BMP file")
    offset = int.from_bytes(header[10:14], "little")
    width = int.from_bytes(header[18:22], "little", signed=True)
    height = int.from_bytes(header[22:26], "little", signed=True)
    bpp = int.from_bytes(header[28:30], "little")
    if bpp != 24:
        raise OSError(f"{path}: expected a 24-bit BMP, got {bpp} bits per pixel")
    stride = (width * 3 + 3) & ~3
    rows = data[offset:offset + stride * abs(height)].reshape(abs(height), stride)[:, : width * 3]
    image = rows.reshape(abs(height), width, 3)[:, :, ::-1]  # BGR -> RGB
    if height > 0:  # bottom-up
        image = image[::-1]
    return np.ascontiguousarray(image)


def to_grayscale(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 1) uint8 BT.601 luma of sRGB bytes (rounded); extra channels (alpha) are ignored."""
    r, g, b = LUMA_601
    luma = rgb[..., 0].astype(np.uint32)
    luma *= r
    for channel, weight in ((1, g), (2, b)):  # in place, channel by channel: 3x faster than a uint32 matmul
        part = rgb[..., channel].astype(np.uint32)
        part *= weight
        luma += part
    luma += 500
    luma //= 1000
    return luma.astype(np.uint8)[:, :, None]


def first_channel(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 1): the red channel (depth renders write the same value to R, G and B)."""
    return np.ascontiguousarray(rgb[:, :, :1])


class QuietStdout:
    """Silences Blender's per-render "Saved: ..." line, which it writes to file descriptor 1.

    Use as a context manager around the render call; the /dev/null descriptor
    stays open for the life of the process, so entering costs two dup2 calls.
    """

    _devnull: int | None = None

    def __enter__(self) -> None:
        with contextlib.suppress(AttributeError, ValueError, OSError):
            sys.stdout.flush()
        if QuietStdout._devnull is None:
            QuietStdout._devnull = os.open(os.devnull, os.O_WRONLY)
        self._saved = os.dup(1)
        os.dup2(QuietStdout._devnull, 1)

    def __exit__(self, *exc: object) -> None:
        os.dup2(self._saved, 1)
        os.close(self._saved)


quiet_stdout = QuietStdout
