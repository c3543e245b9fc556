"""The versions a build record or a training run notes, so a result can be traced to its software."""

from __future__ import annotations

import platform

import numpy as np

__version__ = "0.1.0"


def versions() -> dict[str, str]:
    """visualenv, Gymnasium, numpy, Python and (when bpy imports) Blender versions."""
    import gymnasium

    out = {"visualenv": __version__, "gymnasium": gymnasium.__version__, "numpy": np.__version__, "python": platform.python_version()}
    try:
        import bpy

        out["blender"] = bpy.app.version_string
    except ImportError:  # pragma: no cover - bpy is a dependency
        pass
    return out
