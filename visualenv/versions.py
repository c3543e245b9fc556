"""The versions a build record or a training run notes, so a result can be traced to its software."""

from __future__ import annotations

import platform
from importlib import metadata

import numpy as np

__version__ = "0.1.0"


def installed_version(package: str) -> str | None:
    """An installed package's version, read from its metadata without importing it (bpy takes seconds), or None."""
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def mujoco_version() -> str | None:
    """The installed MuJoCo's version (an optional extra), or None."""
    return installed_version("mujoco")


def versions() -> dict[str, str]:
    """visualenv, Gymnasium, numpy, Python and (where installed) MuJoCo and Blender (bpy's, the same string as
    ``bpy.app.version_string``) versions."""
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
    blender = installed_version("bpy")
    if blender is not None:
        out["blender"] = blender
    return out
