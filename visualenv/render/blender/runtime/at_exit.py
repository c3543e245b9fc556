"""Renderers left open are closed when Python exits, before Blender tears itself down: a quiet exit.

A script that ends with an env still open leaves its Blender scene to Blender's
own exit, which frees it after its GPU (EGL) context is gone: a batch's scene
then printed ``EGL Error (0x3009): EGL_BAD_MATCH ...`` three times on stderr
(a single env's scene happened to free quietly). Removing the scene first is
enough, so every renderer still open closes in an :mod:`atexit` hook, newest
first. The hook is registered after ``bpy`` is imported, and :mod:`atexit`
runs hooks last-registered first: it runs before anything Blender registered.
Closing is the env's job (``env.close()``); this is the safety net for the
scripts that do not.
"""

from __future__ import annotations

import atexit
import contextlib
import weakref
from typing import Any

#: every renderer not yet closed, in the order they were made (weak: a renderer nobody holds goes away as before)
_OPEN: "weakref.WeakValueDictionary[int, Any]" = weakref.WeakValueDictionary()
_made = 0


def track(renderer: Any) -> None:
    """Close `renderer` at exit if it is still open then (its ``close()`` must be safe to call twice)."""
    global _made
    _made += 1
    _OPEN[_made] = renderer


def close_open_renderers() -> None:
    """Close every tracked renderer still open, newest first (a failure to close one leaves the others to close)."""
    for key in sorted(_OPEN.keys(), reverse=True):
        renderer = _OPEN.pop(key, None)
        if renderer is not None:
            with contextlib.suppress(Exception):
                renderer.close()


atexit.register(close_open_renderers)
