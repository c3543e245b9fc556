"""Crater relief for the ``terrain`` primitive: heights of a ground pitted by craters.

Pure numpy, so the shape can be tested without Blender; the Blender backend
moves a grid's vertices to these heights. The profile is the usual one of a
simple crater: a parabolic bowl inside the rim, a raised rim, and ejecta that
fall off as the cube of the distance outside it.
"""

from __future__ import annotations

import numpy as np

from visualenv.spec.models import Craters


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
