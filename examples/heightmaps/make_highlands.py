"""Write examples/heightmaps/highlands.png: a small synthetic lunar DEM (16-bit grayscale PNG, 257 x 257).

    python examples/heightmaps/make_highlands.py [OUT.png]

Rolling highlands (a sum of smooth random waves, seeded) with one large old
crater basin: a stand-in for a real DEM (e.g. a LOLA or HiRISE tile exported as
a 16-bit PNG, TIFF or .npy) in `examples/lunar_dem.yaml`. The same script always
writes the same bytes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

SIDE = 257


def highlands(side: int = SIDE, seed: int = 11) -> np.ndarray:
    """(side, side) heights in 0..1: smooth waves plus a basin with a raised rim, north at row 0."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:side, 0:side] / (side - 1)
    z = np.zeros((side, side))
    for _ in range(24):  # smooth relief: waves of random direction, wavelength 0.15..1 of the tile, amplitude ~ wavelength
        wavelength = rng.uniform(0.15, 1.0)
        angle = rng.uniform(0, 2 * np.pi)
        phase = rng.uniform(0, 2 * np.pi)
        z += wavelength * np.sin(2 * np.pi * (x * np.cos(angle) + y * np.sin(angle)) / wavelength + phase)
    r = np.hypot(x - 0.62, y - 0.4) / 0.22  # a basin east of centre, radius 0.22 of the tile
    z += np.where(r < 1, 1.2 * (r * r - 1) + 0.5, 0.5 / np.maximum(r, 1) ** 3) * 2.5
    z -= z.min()
    return z / z.max()


def main(out: Path) -> None:
    data = np.round(highlands() * 65535).astype(np.uint16)
    Image.fromarray(data).save(out, optimize=True)  # 16-bit grayscale: Pillow writes mode I;16 as a 16-bit PNG
    print(f"wrote {out} ({out.stat().st_size} bytes, {SIDE} x {SIDE}, 16 bit)")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("highlands.png"))
