"""Scripts in a user's .blend never run: Blender's "Auto Run Python Scripts" stays off wherever visualenv loads bpy.

A .blend can carry Python that Blender runs by itself: a text block registered to run when the
file opens, and driver expressions, evaluated whenever the scene is. Blender runs neither while
auto-run (the preference ``filepaths.use_scripts_auto_execute``) is off: a registered text block
is skipped and a driver whose expression is outside Blender's safe subset (arithmetic and math
functions on the driver's variables) evaluates to 0 (checked with bpy 5.0.1). bpy starts with it
off; a process can turn it on (the preference, or opening a file with ``use_scripts=True``), and a
driver is compiled with the setting of the moment it first runs.
So visualenv turns it off when it loads bpy and again before it reads each .blend (setting the
preference also turns off Blender's run-time flag), and refuses to read one if it will not stay off.
Freestyle, which runs line-style scripts even then, is switched off in every render (settings.py).
"""

from __future__ import annotations

import bpy

from visualenv.errors import VisualEnvError


def turn_autorun_off() -> None:
    """Turn Blender's auto-run of scripts in .blend files off, and check that it is off (VisualEnvError if not)."""
    paths = bpy.context.preferences.filepaths
    paths.use_scripts_auto_execute = False  # its update also clears the run-time flag that drivers check
    if paths.use_scripts_auto_execute:
        raise VisualEnvError(
            "Blender's 'Auto Run Python Scripts' is still on after visualenv turned it off: "
            "visualenv reads no .blend file while scripts in it could run"
        )
