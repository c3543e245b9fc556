"""Renders of several scenes in turn in one process, each step several times dearer: said once, with what to do instead.

Blender keeps Cycles' session (kernels, images, BVH, the evaluated scene) for one scene at a time: a render of
another scene frees it, so envs made in one process and stepped in turn (gymnasium's ``SyncVectorEnv``, SB3's
``DummyVecEnv``) each render as if for the first time. One process per env or a batch does not pay it
(docs/performance.md, "Many envs in one process"). An eval env rendered now and then beside a training env is fine:
only a window of renders most of which follow another scene's is told.
"""

from __future__ import annotations

import importlib.util
import os
import traceback
import warnings

#: renders counted before judging, and the share of them that followed another scene's render which is told
WINDOW = 64
SHARE = 0.5
#: the packages between a user's ``step()`` and the render: the warning names the line that called into them
THROUGH = ("visualenv", "gymnasium", "stable_baselines3", "ray")

_last: str | None = None
_renders = 0
_turns = 0
_told = False

MESSAGE = (
    "visualenv: envs in this process render in turn, and Blender rebuilds Cycles' session for each (every step "
    "several times dearer): give each env its own process (visualenv.make_vec, SB3's SubprocVecEnv) or step them as one batch "
    "(visualenv.make_vec(..., batched=True)); see docs/performance.md, 'Many envs in one process'"
)


def rendered(scene: str) -> None:
    """Count a render of `scene`; warn once when most renders of a window followed another scene's render."""
    global _last, _renders, _turns, _told
    if _told:
        return
    _turns += _last is not None and _last != scene
    _last = scene
    _renders += 1
    if _renders < WINDOW:
        return
    if _turns >= SHARE * WINDOW:
        _told = True
        warnings.warn(MESSAGE, RuntimeWarning, stacklevel=_callers_level())
    _renders = _turns = 0


def _callers_level() -> int:
    """The ``stacklevel`` (counted from :func:`rendered`) of the first caller whose file lies outside :data:`THROUGH`."""
    folders = []
    for name in THROUGH:
        found = importlib.util.find_spec(name)
        if found is not None and found.origin:
            folders.append(os.path.dirname(found.origin) + os.sep)
    stack = traceback.extract_stack()[:-1]  # from the outermost call to rendered() (this function left out)
    level = 1
    for frame in reversed(stack):
        if not frame.filename.startswith(tuple(folders)):
            return level
        level += 1
    return 1
