"""Numpy-only picture helpers for previews, recordings and the terminal (no Blender)."""

from __future__ import annotations

from typing import Any

import numpy as np

ASCII_RAMP = " .:-=+*#%@"


def to_rgb(image: np.ndarray) -> np.ndarray:
    return np.repeat(image, 3, axis=2) if image.shape[2] == 1 else image[..., :3]


def side_by_side(observation: Any, view: np.ndarray) -> np.ndarray:
    """Observation(s), scaled up (nearest) to the view's height, left of the view."""
    images = list(observation.values()) if isinstance(observation, dict) else [observation]
    height = view.shape[0]
    panels = []
    for image in images:
        scale = max(1, height // image.shape[0])
        big = np.kron(to_rgb(image), np.ones((scale, scale, 1), dtype=np.uint8))
        pad = np.zeros((height, big.shape[1], 3), np.uint8)
        pad[: min(height, big.shape[0])] = big[:height]
        panels.append(pad)
    gap = np.full((height, 4, 3), 255, np.uint8)
    parts = []
    for panel in panels + [view[..., :3]]:
        parts += [panel, gap]
    return np.concatenate(parts[:-1], axis=1)


def ascii_art(image: np.ndarray, width: int = 50) -> str:
    """A terminal sketch of an image (characters are about twice as tall as wide)."""
    gray = image.astype(np.float32).mean(axis=2)
    h, w = gray.shape
    rows = max(1, int(h * width / w / 2))
    ys = (np.arange(rows) * h / rows).astype(int)
    xs = (np.arange(width) * w / width).astype(int)
    small = gray[np.ix_(ys, xs)]
    idx = (small / 256 * len(ASCII_RAMP)).astype(int).clip(0, len(ASCII_RAMP) - 1)
    return "\n".join("".join(ASCII_RAMP[i] for i in row) for row in idx)
