"""Blender in this process: engine and device settings, what it can render on, its log, a quiet start and exit.

* :mod:`.settings`: engine, preset, device and thread configuration of a scene
* :mod:`.devices`, :mod:`.cuda_kernels`, :mod:`.probe`: Cycles' devices, kernels compiled ahead, ``visualenv info``
* :mod:`.log`: Blender's console output while a scene is built, kept aside
* :mod:`.autorun`: scripts in a user's .blend never run
* :mod:`.at_exit`: renderers left open closed before Blender tears itself down
* :mod:`.scene_turns`: a one-time warning when envs of one process render in turn (each rebuilds Cycles' session)
"""
