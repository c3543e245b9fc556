"""visualenv: compile declarative specs into Gymnasium environments rendered by Blender.

>>> import visualenv
>>> env = visualenv.make("VisualCartPole-v0", render=False)     # state-only, no Blender
>>> obs, info = env.reset(seed=0)

Bundled specs, and those in the folders of ``$VISUALENV_SPECS_PATH``, are registered with
Gymnasium as ``visualenv/<Id>`` on import; ``visualenv.register(path)`` registers your own.
"""

from __future__ import annotations

from visualenv.compiler import compile_spec
from visualenv.env import VisualEnv
from visualenv.env.make import make
from visualenv.errors import ExpressionError, RenderError, SpecError, StepError, VisualEnvError, WorkerError
from visualenv.render.base import RendererOptions
from visualenv.env.registration import register, register_bundled, resolve
from visualenv.spec import load_spec, load_spec_text
from visualenv.versions import __version__
from visualenv.env.sb3_vec import make_sb3_vec
from visualenv.env.vector import make_vec
from visualenv.env.wrappers import FrameStack, Grayscale, Resize, wrap_observation
from visualenv.viewer import register_human_mode

register_bundled()
register_human_mode()  # render_mode="human" shows on the viewer's page, imported by the first human-mode env

__all__ = [
    "__version__",
    "ExpressionError",
    "FrameStack",
    "Grayscale",
    "RenderError",
    "RendererOptions",
    "Resize",
    "SpecError",
    "StepError",
    "VisualEnv",
    "VisualEnvError",
    "WorkerError",
    "compile_spec",
    "load_spec",
    "load_spec_text",
    "make",
    "make_sb3_vec",
    "make_vec",
    "register",
    "register_bundled",
    "resolve",
    "wrap_observation",
]
