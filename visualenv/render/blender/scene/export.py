"""Save a renderer's scene as a .blend file that opens in Blender's GUI."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import bpy


def save_blend(scene: Any, path: str | Path) -> Path:
    """Write `scene` and everything it uses (objects, meshes, materials, world) to `path`.

    Only this scene is written, not the other scenes of the process.
    """
    path = Path(path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.data.libraries.write(str(path), {scene}, path_remap="ABSOLUTE", fake_user=True)
    return path
