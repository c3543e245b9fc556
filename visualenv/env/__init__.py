"""The env layer: the Gymnasium env that runs a compiled program, its wrappers, vector envs and id registration.

Modules: :mod:`~visualenv.env.visual_env` (the env), :mod:`~visualenv.env.make`,
:mod:`~visualenv.env.registration`, :mod:`~visualenv.env.wrappers`, :mod:`~visualenv.env.faults`
(runtime faults located in the spec), :mod:`~visualenv.env.human` (the display ``render_mode="human"`` shows on),
:mod:`~visualenv.env.vector` and :mod:`~visualenv.env.sb3_vec` (one Blender per worker process),
:mod:`~visualenv.env.cores` (cores per worker).
"""

from visualenv.env.visual_env import VisualEnv

__all__ = ["VisualEnv"]
