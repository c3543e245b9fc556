"""Where a file render goes, and keeping Blender's per-render line off stdout.

Blender writes the render to a 24-bit BMP (``write_still``) in ``/dev/shm``
(a RAM disk; falls back to the temp dir), and :func:`visualenv.render.pixels.read_bmp`
views it with numpy. Each renderer owns one file, deleted on close or when the
renderer is garbage-collected (:class:`OutputFile`).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import sys
import tempfile
import weakref

_counter = itertools.count()


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
