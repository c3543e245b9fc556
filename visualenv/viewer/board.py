"""What the viewer's page shows, handed from the thread that steps an env to the server's threads, and the inputs back.

The stepping thread publishes a :class:`Snapshot` (values and pictures) and never waits on the page; each page
connection waits for a newer snapshot and sends it. Pictures are kept as arrays and encoded by the server only when
a page asks, so an env that nobody watches pays for a copy of its observation, no more.
"""

from __future__ import annotations

import queue
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Iterator, Mapping

import numpy as np

#: picture kinds: what the agent sees (shown upscaled without smoothing) and the high-resolution view
OBSERVATION, VIEW = "observation", "view"
#: at most this share of the stepping thread's time goes to rendering views while it runs (see :class:`ViewPacer`)
VIEW_SHARE = 0.25
#: inputs that may wait for the stepping thread; the server refuses more (503) until it takes them
MAX_QUEUED_INPUTS = 256


@dataclass(frozen=True)
class Picture:
    """An image of the page: (H, W, C) uint8 with C 1 (gray), 3 (RGB) or 4 (RGBA); `version` changes when it does."""

    pixels: np.ndarray
    kind: str
    version: int


@dataclass(frozen=True)
class Snapshot:
    """Everything the page shows at one moment: JSON-safe values and the pictures by name."""

    version: int = 0
    values: Mapping[str, Any] = field(default_factory=dict)
    pictures: Mapping[str, Picture] = field(default_factory=dict)


class Board:
    """The latest snapshot, with a condition the page connections wait on, and the page's inputs in a queue."""

    def __init__(self) -> None:
        self._condition = threading.Condition()
        self._snapshot = Snapshot()
        self._watchers = 0
        self._closed = False
        #: inputs from the page (dicts checked by the server), read by the stepping thread
        self.inputs: queue.Queue[dict[str, Any]] = queue.Queue(maxsize=MAX_QUEUED_INPUTS)

    def publish(
        self,
        values: Mapping[str, Any],
        pictures: Mapping[str, Any] | None = None,
        *,
        kind: str = OBSERVATION,
        only: bool = False,
    ) -> None:
        """A new snapshot: `values` replace the old ones; `pictures` (arrays by name, of `kind`; None removes one) replace
        theirs, and with `only` every other picture of that kind goes (a rebuilt env may have other cameras)."""
        with self._condition:
            old = self._snapshot
            version = old.version + 1
            kept = {name: p for name, p in old.pictures.items() if not (only and p.kind == kind)}
            for name, pixels in (pictures or {}).items():
                if pixels is None:
                    kept.pop(name, None)
                else:
                    kept[name] = Picture(as_image(pixels), kind, version)
            self._snapshot = Snapshot(version, dict(values), kept)
            self._condition.notify_all()

    def update(self, **values: Any) -> None:
        """The same pictures with some values changed (paused, speed, an error)."""
        with self._condition:
            self.publish({**self._snapshot.values, **values})

    def latest(self) -> Snapshot:
        return self._snapshot

    def wait(self, after: int, timeout: float) -> Snapshot:
        """The first snapshot newer than version `after`, or the latest one after `timeout` seconds or once closed."""
        with self._condition:
            self._condition.wait_for(lambda: self._snapshot.version > after or self._closed, timeout)
            return self._snapshot

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Ends every page connection's wait (the server is stopping)."""
        with self._condition:
            self._closed = True
            self._condition.notify_all()

    @contextmanager
    def watching(self) -> Iterator[None]:
        """Held while a page is connected: views are rendered only while someone watches."""
        with self._condition:
            self._watchers += 1
        try:
            yield
        finally:
            with self._condition:
                self._watchers -= 1

    @property
    def watched(self) -> bool:
        return self._watchers > 0


class ViewPacer:
    """When to render the high-resolution view while an env runs: at most :data:`VIEW_SHARE` of the time.

    A Cycles view of a few hundred pixels takes many times an observation's render; rendered every step it would
    set the pace. After a view that took t seconds, the next one is due (1 / share - 1) * t seconds after it ended.
    """

    def __init__(self, share: float = VIEW_SHARE) -> None:
        self._wait_factor = 1.0 / share - 1.0
        self._due = 0.0

    def due(self) -> bool:
        return time.monotonic() >= self._due

    def took(self, started: float) -> None:
        """A view that began at `started` (time.monotonic()) has just ended."""
        now = time.monotonic()
        self._due = now + self._wait_factor * (now - started)


def as_image(pixels: Any) -> np.ndarray:
    """An (H, W, C) uint8 copy with C in 1, 3, 4: what the server can encode (a 2-D array is one gray channel)."""
    array = np.asarray(pixels)
    if array.ndim == 2:
        array = array[:, :, None]
    if array.ndim != 3 or array.shape[2] not in (1, 3, 4):
        raise ValueError(f"a picture is (H, W) or (H, W, C) with C 1, 3 or 4, got shape {array.shape}")
    if array.dtype != np.uint8:
        array = np.clip(array, 0, 255).astype(np.uint8)
    return np.array(array, copy=True)


def observation_pictures(observation: Any) -> dict[str, np.ndarray]:
    """The images of an observation by name: one array as 'observation', a Dict observation by its keys."""
    if observation is None:
        return {}
    if isinstance(observation, Mapping):
        return {str(key): value for key, value in observation.items() if _is_image(value)}
    return {"observation": observation} if _is_image(observation) else {}


def plain(value: Any) -> Any:
    """`value` as JSON can hold it: numpy scalars and arrays as numbers and lists, non-finite floats as text."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        number = float(value)
        return number if np.isfinite(number) else str(number)
    if value is None or isinstance(value, str):
        return value
    return str(value)


def _is_image(value: Any) -> bool:
    shape: tuple[int, ...] = getattr(value, "shape", ())
    return len(shape) == 3 and shape[2] in (1, 3, 4) or len(shape) == 2 and min(shape) > 1
