"""Gymnasium's internals visualenv reads: the limit ``make``'s TimeLimit wrapper truncates at, a space's generator.

**The limit of** ``make`` (:func:`make_time_limit`): the ``max_episode_steps`` of the TimeLimit wrapper, for the env
inside it.

Why the env needs it: Gymnasium truncates in the ``TimeLimit`` wrapper that ``gymnasium.make`` puts around the
env, outside it, where ``info["outcome"]`` cannot be set; a visualenv env truncates at the same step itself and
says ``"max_steps"`` (and does not end an episode at its spec's ``max_steps`` when the limit asked for is longer).

The documented route does not reach the env. ``gymnasium.make`` passes ``max_episode_steps`` to no entry point,
and the spec it sets on the env (``env.unwrapped.spec``, the one an env can read at reset) has
``max_episode_steps=None``: the limit is kept by the wrapper alone, whose ``env.spec`` (outside) is the only
documented place that holds it. So :func:`make_time_limit` reads it from ``gymnasium.make``'s own frame while
``make`` calls the entry point: its argument ``max_episode_steps``, else its ``env_spec``'s. It does so on the
versions in :data:`CHECKED` alone, and only when ``gymnasium.make`` is the entry point's caller; elsewhere it
gives None (the env then truncates at its spec's ``max_steps``). ``tests/compat/test_gymnasium.py`` fails when
Gymnasium moves: another version, or a ``make`` that sets the limit on the env's spec (the documented route
this module should then take instead).

**A space's generator** (:func:`space_generator`, :func:`restore_space_generator`): a pickled env carries its action
space's generator over, so that ``action_space.sample()`` goes on as it would have. The space makes its generator on
first use of ``space.np_random`` (seeding a new one from the OS), which a pickled env must not do to an unused space;
the generator it holds, or None, is in ``space._np_random``, and there alone can it be put back (``np_random`` has no
setter; ``space.seed`` makes a new generator). Gymnasium's own pickling of a space carries it in that attribute too.

Checked against Gymnasium 1.0.0, 1.1.1 and 1.2.2, whose ``make`` and ``Space`` are the same code in these parts.
"""

from __future__ import annotations

import sys
from typing import Any

import gymnasium

#: the Gymnasium versions (major.minor) whose ``make`` and ``Space`` were read for what this module relies on
CHECKED = ("1.0", "1.1", "1.2")


def checked() -> bool:
    """Whether the installed Gymnasium is one this module was checked against."""
    return ".".join(gymnasium.__version__.split(".")[:2]) in CHECKED


def make_time_limit() -> int | None:
    """The ``max_episode_steps`` of the TimeLimit wrapper that ``gymnasium.make`` will put around the env being made.

    Call it from the entry point itself: the frame two up (this function's caller's caller) must be ``gymnasium.make``'s;
    any other caller, or a Gymnasium not in :data:`CHECKED`, gives None.
    """
    if not checked():
        return None
    frame = sys._getframe(2)  # make_time_limit <- the entry point <- its caller
    if frame.f_code is not gymnasium.envs.registration.make.__code__:
        return None
    steps = frame.f_locals.get("max_episode_steps")
    if steps is None:
        steps = getattr(frame.f_locals.get("env_spec"), "max_episode_steps", None)
    return steps if isinstance(steps, int) and not isinstance(steps, bool) and steps > 0 else None


def space_generator(space: gymnasium.spaces.Space[Any]) -> Any:
    """The generator `space` samples from (a numpy Generator), or None where it has made none yet; read without making
    one (``space.np_random`` would)."""
    return getattr(space, "_np_random", None)


def restore_space_generator(space: gymnasium.spaces.Space[Any], generator: Any) -> None:
    """`generator` (from :func:`space_generator`) put back as the one `space` samples from."""
    space._np_random = generator
