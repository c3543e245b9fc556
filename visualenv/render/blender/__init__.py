"""The Blender backend: builds the scene with ``bpy`` and renders cameras to numpy arrays.

Modules, one job each:

* :mod:`.scene`: load a .blend / build primitives, meshes, lights, cameras; track created data
* :mod:`.materials`: Principled BSDF materials, textures, the world, the depth material
* :mod:`.settings`: engine, preset, device and thread configuration
* :mod:`.readback`: rendered pixels to numpy
* :mod:`.devices`: Cycles devices, the GPU context, kernel caches (``visualenv info``)
* :mod:`.blendfile`, :mod:`.describe`: a user's .blend read in a child process first
* :mod:`.autorun`: scripts in a .blend never run (Blender's auto-run off, checked before every read)
* :mod:`.renderer`: :class:`BlenderRenderer`, the :class:`~visualenv.render.base.Renderer` the env uses

Importing this package imports ``bpy`` and turns Blender's auto-run of scripts in .blend files off.
"""

from visualenv.compat.blender import drop_inherited_script_paths

drop_inherited_script_paths()  # before anything imports bpy

from visualenv.render.blender.autorun import turn_autorun_off  # noqa: E402
from visualenv.render.blender.renderer import BlenderRenderer  # noqa: E402

turn_autorun_off()

__all__ = ["BlenderRenderer"]
