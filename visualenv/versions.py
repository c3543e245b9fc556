"""The versions a build record or a training run notes, so a result can be traced to its software."""

from __future__ import annotations

import platform
from importlib import metadata

import numpy as np

__version__ = "0.1.0"


def mujoco_version() -> str | None:
    """The installed MuJoCo's version (an optional extra; read from its metadata, without importing it), or None."""
    try:
        return metadata.version("mujoco")
    except metadata.PackageNotFoundError:
        return None


def versions() -> dict[str, str]:
    """visualenv, Gymnasium, numpy, Python and (where installed) MuJoCo and (when bpy imports) Blender versions."""
    import gymnasium

    out = {
        "visualenv": __version__,
        "gymnasium": gymnasium.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
    }
    mujoco = mujoco_version()
    if mujoco is not None:
        out["mujoco"] = mujoco
    try:
        import bpy

        out["blender"] = bpy.app.version_string
    except ImportError:  # pragma: no cover - bpy is a dependency
        pass
    return out
