"""Write the images of specs/goalie_randomized.yaml: three field textures and a sky (PNG, made here, seeded).

    python specs/assets/make_goalie_assets.py [OUT_FOLDER]

Each field texture is a pattern of Voronoi-like cells (about 16 across, so 2.5 m
cells on Goalie's 40 m field, as its procedural texture) in two shades of one
colour: fresh grass, dry grass and a blue-green artificial turf, of different
brightness. The sky is an equirectangular panorama, pale at the horizon and deeper
blue overhead, with soft clouds. The same script always writes the same bytes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

FIELDS = {
    "field_grass.png": ((0.03, 0.12, 0.03), (0.08, 0.25, 0.06)),
    "field_dry.png": ((0.20, 0.18, 0.06), (0.36, 0.32, 0.12)),
    "field_turf.png": ((0.02, 0.10, 0.12), (0.05, 0.20, 0.22)),
}


def cells(side: int, per_side: int, seed: int) -> np.ndarray:
    """(side, side) in 0..1: distance to the nearest cell point, one random point per cell of a per_side x per_side grid (wrapping)."""
    rng = np.random.default_rng(seed)
    size = side / per_side
    offsets = rng.random((per_side, per_side, 2))  # each cell's point, as a fraction of the cell: (y, x)
    y, x = np.mgrid[0:side, 0:side].astype(float)
    row, col = (y // size).astype(int), (x // size).astype(int)
    best = np.full((side, side), np.inf)
    for dr in (-1, 0, 1):  # the nearest point lies in this cell or a neighbour
        for dc in (-1, 0, 1):
            r, c = (row + dr) % per_side, (col + dc) % per_side
            dy = np.abs(y - (r + offsets[r, c, 0]) * size)
            dx = np.abs(x - (c + offsets[r, c, 1]) * size)
            best = np.minimum(best, np.hypot(np.minimum(dx, side - dx), np.minimum(dy, side - dy)))
    return best / best.max()


def srgb(linear: np.ndarray) -> np.ndarray:
    """Linear 0..1 to sRGB bytes (PNG colour textures are read as sRGB)."""
    encoded = np.where(linear <= 0.0031308, linear * 12.92, 1.055 * np.power(np.clip(linear, 0, 1), 1 / 2.4) - 0.055)
    return np.round(np.clip(encoded, 0, 1) * 255).astype(np.uint8)


def field(dark: tuple, light: tuple, seed: int, side: int = 256) -> np.ndarray:
    t = cells(side, 16, seed)[..., None]
    return srgb(np.array(dark) * (1 - t) + np.array(light) * t)


def sky(width: int = 256, height: int = 128, seed: int = 5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    elevation = (0.5 - (np.arange(height) + 0.5) / height) * np.pi  # +pi/2 at the top row
    up = np.clip(np.sin(elevation), 0, 1)[:, None, None]
    horizon, zenith, ground = np.array([0.75, 0.8, 0.85]), np.array([0.25, 0.45, 0.85]), np.array([0.3, 0.28, 0.25])
    base = np.where(elevation[:, None, None] >= 0, horizon * (1 - up) + zenith * up, ground)
    clouds = np.zeros((height, width))
    for _ in range(30):  # soft blobs above the horizon
        cx, cy, r = rng.uniform(0, width), rng.uniform(height * 0.1, height * 0.45), rng.uniform(6, 20)
        y, x = np.mgrid[0:height, 0:width]
        dx = np.minimum(np.abs(x - cx), width - np.abs(x - cx))  # the panorama wraps around
        clouds += np.exp(-(dx**2 + ((y - cy) * 2) ** 2) / (2 * r * r))
    clouds = np.clip(clouds, 0, 1)[..., None]
    return srgb(base * (1 - 0.7 * clouds) + 0.95 * 0.7 * clouds)


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for i, (name, (dark, light)) in enumerate(FIELDS.items()):
        Image.fromarray(field(dark, light, seed=i)).save(out / name, optimize=True)
    Image.fromarray(sky()).save(out / "sky.png", optimize=True)
    print(f"wrote {', '.join(sorted(p.name for p in out.glob('*.png')))} to {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("goalie"))
