"""Numpy-only pixel conversions shared by the renderer and the wrappers (importing this never starts Blender).

One BT.601 grayscale (:func:`to_grayscale`) serves the Blender readback and the
:class:`~visualenv.env.wrappers.Grayscale` wrapper; the capture's table-driven fast
path produces the same bytes from the same :data:`LUMA_601` weights.
"""

from __future__ import annotations

import numpy as np

#: ITU-R BT.601 luma weights (the same as OpenCV's and Pillow's "L" conversion), applied to sRGB bytes
LUMA_601 = (299, 587, 114)


def read_bmp(path: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB, top row first, from an uncompressed 24-bit BMP.

    BMP rows are bottom-up, padded to 4 bytes and in BGR order; the view is flipped here so row 0 is the top.
    """
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
    rows = data[offset : offset + stride * abs(height)].reshape(abs(height), stride)[:, : width * 3]
    image = rows.reshape(abs(height), width, 3)[:, :, ::-1]  # BGR -> RGB
    if height > 0:  # bottom-up
        image = image[::-1]
    return np.ascontiguousarray(image)


def to_grayscale(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 1) uint8 BT.601 luma of sRGB bytes (rounded); extra channels (alpha) are ignored."""
    r, g, b = LUMA_601
    luma = rgb[..., 0].astype(np.uint32)
    luma *= r
    for channel, weight in ((1, g), (2, b)):  # in place, per channel: faster than a uint32 matmul
        part = rgb[..., channel].astype(np.uint32)
        part *= weight
        luma += part
    luma += 500
    luma //= 1000
    return luma.astype(np.uint8)[:, :, None]


def first_channel(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 1): the red channel (depth renders write the same value to R, G and B)."""
    return np.ascontiguousarray(rgb[:, :, :1])
