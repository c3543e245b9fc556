"""`visualenv.make`: one env from a spec path, a build folder or an id; also the entry point of the registered ids."""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec

from visualenv.compat.gymnasium import make_time_limit
from visualenv.env.registration import ENTRY_POINT, NAMESPACE, VECTOR_ENTRY_POINT, resolve
from visualenv.env.visual_env import VisualEnv
from visualenv.env.wrappers import wrap_observation
from visualenv.compiler.render_plan import checked_options
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
    max_episode_steps: int | None = None,
    action_repeat: int | None = None,
    distractions: float | str | dict[str, Any] | None = None,
    trust_code: bool = False,
    **renderer_options: Any,
) -> gym.Env:
    """Make an env from a spec path, a build folder (``build/<Id>``) or an id.

    Args:
        target: ``specs/visual_cartpole.yaml``, ``build/VisualCartPole-v0`` or ``VisualCartPole-v0``.
        render: False for the state-only env (observation = state vector, no
            Blender); default: render when the spec has an ``observation``.
        render_mode: ``"rgb_array"`` to make ``env.render()`` return the high-resolution view; ``"human"`` to watch every
            step on a local web page (docs/viewer.md).
        params: overrides of the spec's ``params``.
        frame_stack, grayscale, resize: image wrappers (see :mod:`visualenv.env.wrappers`).
        max_episode_steps: truncate episodes after this many steps instead of the spec's ``max_steps``
            (``info["outcome"]`` says ``"max_steps"``); ``gymnasium.make(id, max_episode_steps=N)`` sets it too.
        action_repeat: the spec's steps per ``step()`` with the same action, rewards summed, one observation
            (dm_control's action repeat); default: the spec's ``action_repeat`` (``DMC-cartpole-swingup-v0``: 8).
        distractions: what the observation shows changed per episode, the state and rewards untouched: a difficulty in
            [0, 1] (every kind, fixed per episode), a level of the Distracting Control Suite by name (``"easy"``,
            ``"medium"``, ``"hard"``: 0.1, 0.2, 0.3) or the spec's ``distractions`` section as a dict
            (docs/distractions.md); default: the spec's; 0: none.
        trust_code: import the module a spec's ``dynamics.python`` names (its code runs): give it only for a spec
            whose author you trust (docs/security.md); without it such a spec raises :class:`SpecError`.
        renderer_options: passed to the renderer (``device``, ``threads``, ``engine``, ``samples``, ``readback``).

    Every option is checked as the same value in a spec would be (``device="tpu"``,
    ``samples=0`` or ``resize="64"`` raise :class:`SpecError` naming the option).
    The env's ``spec`` is a Gymnasium ``EnvSpec`` that makes the same env again
    (``env.spec.make(render_mode=...)``, as ``check_env`` does).
    """
    if max_episode_steps is None:
        # gymnasium.make's, when it is the caller (its TimeLimit truncates outside the env)
        max_episode_steps = make_time_limit()
    check_make_options(
        render=render,
        render_mode=render_mode,
        params=params,
        frame_stack=frame_stack,
        grayscale=grayscale,
        resize=resize,
        max_episode_steps=max_episode_steps,
        action_repeat=action_repeat,
        distractions=distractions,
        trust_code=trust_code,
    )
    options = checked_options(renderer_options)
    path = resolve(target)
    unwrapped = VisualEnv(
        load_spec(path),
        render=render,
        render_mode=render_mode,
        params=params,
        renderer_options=options,
        max_episode_steps=max_episode_steps,
        action_repeat=action_repeat,
        distractions=distractions,
        trust_code=trust_code,
    )
    given = {
        "render": render,
        "render_mode": render_mode,
        "params": params,
        "frame_stack": frame_stack,
        "grayscale": grayscale or None,
        "resize": resize,
        "action_repeat": action_repeat,
        "distractions": distractions,
        "trust_code": trust_code or None,
        **renderer_options,
    }
    unwrapped.spec = EnvSpec(
        id=f"{NAMESPACE}/{unwrapped.program.spec.id}",
        entry_point=ENTRY_POINT,
        vector_entry_point=VECTOR_ENTRY_POINT,
        max_episode_steps=unwrapped.max_episode_steps,
        kwargs={"target": str(path.resolve()), **{k: v for k, v in given.items() if v is not None}},
    )
    return wrap_observation(unwrapped, grayscale=grayscale, resize=resize, frame_stack=frame_stack)
