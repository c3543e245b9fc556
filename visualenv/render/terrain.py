"""Relief for the ``terrain`` primitive: elevation data read from a file, and craters pressed into it.

Pure numpy (and Pillow for images), so the shape can be tested without Blender; the Blender backend
moves a grid's vertices to these heights. The profile is the usual one of a
simple crater: a parabolic bowl inside the rim, a raised rim, and ejecta that
fall off as the cube of the distance outside it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from visualenv.files import MAX_IMAGE_PIXELS, FileSizeError, check_image, npy_header
from visualenv.render.plan import Craters


def crater_field(craters: Craters, extent: tuple[float, float]) -> np.ndarray:
    """(count, 3) array of crater centres x, y and radii, drawn from ``craters.seed`` over a ground of this [x, y] extent."""
    rng = np.random.default_rng(craters.seed)
    low, high = craters.radius
    radii = np.exp(rng.uniform(np.log(low), np.log(high), craters.count))
    xs = rng.uniform(-extent[0] / 2, extent[0] / 2, craters.count)
    ys = rng.uniform(-extent[1] / 2, extent[1] / 2, craters.count)
    return np.stack([xs, ys, radii], axis=1)


def crater_heights(x: np.ndarray, y: np.ndarray, craters: Craters, extent: tuple[float, float]) -> np.ndarray:
    """Height of the ground at the points (x, y): every crater's bowl, rim and ejecta, added up."""
    z = np.zeros(np.broadcast(x, y).shape)
    for cx, cy, radius in crater_field(craters, extent):
        diameter = 2.0 * radius
        rim = craters.rim * diameter
        r = np.hypot(x - cx, y - cy) / radius
        inside = r < 1.0
        # bowl: rim - depth at the centre, rim at r = 1; outside, the rim's height decays as r**-3
        z += np.where(inside, rim + craters.depth * diameter * (r * r - 1.0), rim / np.maximum(r, 1.0) ** 3)
    return z


#: Pillow modes of single-channel images (8-bit, 16-bit, 32-bit integer, 32-bit float): elevation, not colour
_GRAY_MODES = ("L", "I;16", "I;16B", "I;16L", "I", "F")


class HeightmapError(ValueError):
    """A heightmap file that cannot be read as elevation data; the message says why and what is accepted."""


def read_heightmap(path: Path, max_pixels: int = MAX_IMAGE_PIXELS) -> np.ndarray:
    """(rows, columns) float64 in 0..1 from a grayscale image or a .npy array: the lowest value 0, the highest 1.

    Row 0 is the north edge (+y), column 0 the west edge (-x), as a map is drawn.
    A flat map gives zeros. Colour images are refused (which channel is the height?). The size is read from the
    file's header first: more than `max_pixels` values (``scene.max_image_pixels``) are refused before any is read.
    """
    if not path.is_file():
        raise HeightmapError("heightmap file " + ("is a folder" if path.is_dir() else "not found") + f": {path}")
    if path.suffix.lower() == ".npy":
        try:
            shape, dtype = npy_header(path, max_pixels)
        except FileSizeError as exc:
            raise HeightmapError(
                f"{path}: {exc} (read before the array is; scene.max_image_pixels raises the limit)"
            ) from None
        except (OSError, ValueError) as exc:
            raise HeightmapError(f"cannot read {path} as a .npy array: {exc}") from None
        if len(shape) != 2 or dtype.kind not in "iuf":
            raise HeightmapError(f"{path}: a heightmap array must be 2-D numbers, got shape {shape} of {dtype}")
        try:
            data = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise HeightmapError(f"cannot read {path} as a .npy array: {exc}") from None
    else:
        from PIL import Image, UnidentifiedImageError

        try:
            check_image(path, max_pixels, "scene.max_image_pixels")
        except FileSizeError as exc:
            raise HeightmapError(str(exc)) from None
        except OSError as exc:
            raise HeightmapError(f"cannot read {path}: {exc}") from None
        try:
            with Image.open(path) as image:
                if image.mode not in _GRAY_MODES:
                    raise HeightmapError(
                        f"{path} is a {image.mode} image: a heightmap is one channel (grayscale PNG of 8 or 16 bits, "
                        "a 1-band TIFF, or a .npy array)"
                    )
                data = np.array(image)
        except (OSError, UnidentifiedImageError, Image.DecompressionBombError) as exc:
            raise HeightmapError(f"cannot read {path} as an image (PNG, TIFF) or .npy array: {exc}") from None
    heights = data.astype(np.float64)
    if min(heights.shape) < 2:
        raise HeightmapError(
            f"{path}: a heightmap needs at least 2 x 2 values, got {heights.shape[1]} x {heights.shape[0]}"
        )
    if not np.isfinite(heights).all():
        raise HeightmapError(f"{path}: the heightmap holds NaN or infinite values (fill the voids of the DEM first)")
    low, high = heights.min(), heights.max()
    return (heights - low) / (high - low) if high > low else np.zeros_like(heights)


def heightmap_heights(
    x: np.ndarray, y: np.ndarray, heights: np.ndarray, size: tuple[float, float, float]
) -> np.ndarray:
    """Height at the points (x, y) of a ground of ``size`` [x, y, z] centred on the origin: the map sampled bilinearly, scaled to z."""
    rows, cols = heights.shape
    u = np.clip((np.asarray(x) / size[0] + 0.5) * (cols - 1), 0, cols - 1)
    v = np.clip((0.5 - np.asarray(y) / size[1]) * (rows - 1), 0, rows - 1)
    c0 = np.minimum(np.floor(u).astype(int), cols - 2)
    r0 = np.minimum(np.floor(v).astype(int), rows - 2)
    fu, fv = u - c0, v - r0
    top = heights[r0, c0] * (1 - fu) + heights[r0, c0 + 1] * fu
    bottom = heights[r0 + 1, c0] * (1 - fu) + heights[r0 + 1, c0 + 1] * fu
    return (top * (1 - fv) + bottom * fv) * size[2]
