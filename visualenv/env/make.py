"""`visualenv.make`: one env from a spec path, a build folder or an id; also the entry point of the registered ids."""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym

from visualenv.env.registration import resolve
from visualenv.env.visual_env import VisualEnv
from visualenv.env.wrappers import wrap_observation
from visualenv.render.base import RendererOptions
from visualenv.spec.loader import load_spec
from visualenv.spec.options import check_make_options


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
        frame_stack, grayscale, resize: image wrappers (see :mod:`visualenv.env.wrappers`).
        renderer_options: passed to the renderer (``device``, ``threads``, ``engine``, ``samples``, ``readback``).

    Every option is checked as the same value in a spec would be (``device="tpu"``,
    ``samples=0`` or ``resize="64"`` raise :class:`SpecError` naming the option).
    """
    check_make_options(render=render, render_mode=render_mode, params=params, frame_stack=frame_stack, grayscale=grayscale, resize=resize)
    options = RendererOptions.parse(renderer_options)
    env: gym.Env = VisualEnv(load_spec(resolve(target)), render=render, render_mode=render_mode, params=params, renderer_options=options)
    return wrap_observation(env, grayscale=grayscale, resize=resize, frame_stack=frame_stack)
