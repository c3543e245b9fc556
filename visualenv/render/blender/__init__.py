"""The Blender backend: builds the scene with ``bpy`` and renders cameras to numpy arrays.

Modules and packages, one job each:

* :mod:`.renderer`: :class:`BlenderRenderer`, the :class:`~visualenv.render.base.Renderer` of one env (N = 1)
* :mod:`.binding_setters`: how each bound property is written into the scene (the renderers' setters)
* :mod:`.capture`, :mod:`.readback`: rendered pixels to numpy (in memory, or through a file)
* :mod:`.scene`: building the scene (primitives, a user's .blend, MJCF models)
* :mod:`.look`: materials, the world, MuJoCo's look, distractions, segmentation
* :mod:`.batch`: many envs in one scene (copies, instances, the tiles camera): the renderer of N > 1
* :mod:`.runtime`: settings, devices, Blender's log, auto-run off, a quiet exit

Importing this package imports ``bpy`` and turns Blender's auto-run of scripts in .blend files off.
"""

from visualenv.compat.blender import drop_inherited_script_paths

drop_inherited_script_paths()  # before anything imports bpy

from visualenv.render.blender.runtime.autorun import turn_autorun_off  # noqa: E402
from visualenv.render.blender.renderer import BlenderRenderer  # noqa: E402

turn_autorun_off()

__all__ = ["BlenderRenderer"]
