"""visualenv: compile declarative specs into Gymnasium environments rendered by Blender.

>>> import visualenv
>>> env = visualenv.make("VisualCartPole-v0", render=False)     # state-only, no Blender
>>> obs, info = env.reset(seed=0)

Bundled specs are registered with Gymnasium as ``visualenv/<Id>`` on import.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym

from visualenv.compiler import compile_spec
from visualenv.env import VisualEnv
from visualenv.errors import ExpressionError, RenderError, SpecError, StepError, VisualEnvError, WorkerError
from visualenv.options import check_make_options
from visualenv.render.base import RendererOptions
from visualenv.registration import register_bundled, resolve
from visualenv.spec import load_spec, load_spec_text
from visualenv.sb3_vec import make_sb3_vec
from visualenv.vector import make_vec
from visualenv.wrappers import FrameStack, Grayscale, Resize, wrap_observation

__version__ = "0.1.0"


def make(
    target: str | os.PathLike[str],
    *,
    render: bool | None = None,
    render_mode: str | None = None,
    params: dict[str, Any] | None = None,
    frame_stack: int | None = None,
    grayscale: bool = False,
    resize: tuple[int, int] | None = None,
    **renderer_options: Any,
) -> gym.Env:
    """Make an env from a spec path, a build folder (``build/<Id>``) or an id.

    Args:
        target: ``specs/visual_cartpole.yaml``, ``build/VisualCartPole-v0`` or ``VisualCartPole-v0``.
        render: False for the state-only env (observation = state vector, no
            Blender); default: render when the spec has an ``observation``.
        render_mode: ``"rgb_array"`` to make ``env.render()`` return the high-resolution view.
        params: overrides of the spec's ``params``.
        frame_stack, grayscale, resize: image wrappers (see :mod:`visualenv.wrappers`).
        renderer_options: passed to the renderer (``device``, ``threads``, ``engine``, ``samples``, ``readback``).

    Every option is checked as the same value in a spec would be (``device="tpu"``,
    ``samples=0`` or ``resize="64"`` raise :class:`SpecError` naming the option).
    """
    check_make_options(render=render, render_mode=render_mode, params=params, frame_stack=frame_stack, grayscale=grayscale, resize=resize)
    options = RendererOptions.parse(renderer_options)
    env: gym.Env = VisualEnv(load_spec(resolve(target)), render=render, render_mode=render_mode, params=params, renderer_options=options)
    return wrap_observation(env, grayscale=grayscale, resize=resize, frame_stack=frame_stack)


register_bundled()

__all__ = [
    "ExpressionError", "FrameStack", "Grayscale", "RenderError", "RendererOptions", "Resize", "SpecError", "StepError", "VisualEnv",
    "VisualEnvError", "WorkerError", "compile_spec", "load_spec", "load_spec_text", "make", "make_sb3_vec", "make_vec", "register_bundled",
    "resolve", "wrap_observation",
]
