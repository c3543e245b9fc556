"""``render_mode="human"``: the hook through which an env shows its steps on a display that sits above it.

The env layer does not import the viewer (it is two layers up). It names what a display must do
(:class:`HumanDisplay`), and a display registers a factory with :func:`register_human_display`. ``import visualenv``
registers the viewer's page (docs/viewer.md), whose web server is imported only when the first human-mode env shows
a step. Another display (a window, a test's recorder) registers its own factory in the viewer's place.

A batch shows its observations tiled into one picture by :func:`grid`.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping, Protocol

import numpy as np

from visualenv.errors import VisualEnvError

#: the most envs a batch's grid shows (a batch of thousands would make a picture nobody can read)
GRID_LIMIT = 64


class HumanDisplay(Protocol):
    """What a human-mode env calls on its display: one is opened (by the factory) at the env's first shown step."""

    def show(
        self, title: str, observation: Any, values: Mapping[str, Any], view: Callable[[], np.ndarray] | None = None
    ) -> None:
        """A reset or step of the env titled `title`.

        `observation`: the image observation (an array, or a dict of arrays by camera; None for a state vector; a
        batch's :func:`grid`). `values`: the env's info with ``reward`` (None at a reset); a batch passes ``envs``,
        ``steps`` and ``state`` and no reward. `view`: renders the env's high-resolution view when called (None for
        a batch); a display calls it only when it has somewhere to show it.
        """

    def close(self) -> None:
        """The env closed."""


_factory: Callable[[], HumanDisplay] | None = None


def register_human_display(factory: Callable[[], HumanDisplay] | None) -> Callable[[], HumanDisplay] | None:
    """Makes `factory` open the display of every human-mode env from now on (None: no display); returns the factory
    it replaces."""
    global _factory
    previous, _factory = _factory, factory
    return previous


def open_human_display() -> HumanDisplay:
    """A new display from the registered factory, for one human-mode env; a clear error where none is registered."""
    if _factory is None:
        raise VisualEnvError(
            "render_mode='human' needs a display and none is registered: `import visualenv` registers the viewer's "
            "page; another display registers a factory with visualenv.env.human.register_human_display(factory)"
        )
    return _factory()


def grid(batch: np.ndarray, limit: int = GRID_LIMIT) -> np.ndarray:
    """The first `limit` images of an (N, H, W, C) batch tiled row by row in a near-square grid, 1 px apart."""
    images = np.asarray(batch)[:limit]
    n, h, w, c = images.shape
    columns = int(np.ceil(np.sqrt(n)))
    rows = int(np.ceil(n / columns))
    out = np.zeros((rows * (h + 1) - 1, columns * (w + 1) - 1, c), dtype=images.dtype)
    for i in range(n):
        r, k = divmod(i, columns)
        out[r * (h + 1) : r * (h + 1) + h, k * (w + 1) : k * (w + 1) + w] = images[i]
    return out
