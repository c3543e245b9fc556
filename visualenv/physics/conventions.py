"""How a simulation steps, resets and draws: as Gymnasium's ``MujocoEnv`` or as dm_control's ``Physics``, call for call.

A spec names its convention (``physics.convention``) and the env makes the same MuJoCo
calls, in the same order, as the library it reproduces, so the same actions give the same
state to the last bit:

* ``gymnasium``: a step is ``mj_step(nstep)`` then ``mj_rnePostConstraint``; a reset is
  ``mj_resetData``, the reset values, ``mj_forward``; draws come from Gymnasium's
  ``np_random`` (a ``Generator``).
* ``dm_control``: a step is dm_control's ``Physics.step`` with ``legacy_step`` (RK4:
  ``mj_step(nstep)``; other integrators: ``mj_step2``, ``mj_step(nstep - 1)``; then
  ``mj_step1``, so positions and velocities, and what depends on them, are up to date when
  the reward reads them); a reset is ``mj_resetData`` then ``mj_forward`` with actuation
  disabled (``Physics.reset``), the reset values, and ``mj_forward`` with actuation disabled
  again (``Physics.after_reset``); draws come from a ``numpy.random.RandomState(seed)``, as
  ``suite.load(..., task_kwargs={"random": seed})`` makes its task's, continued from
  episode to episode.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

CONVENTIONS = ("gymnasium", "dm_control")
#: a seed for the legacy stream is below this (RandomState's limit)
LEGACY_SEED_LIMIT = 2**32

#: one call that advances MuJoCo by `nstep` physics steps: (model, data, nstep)
Step = Callable[[Any, Any, int], None]
#: one call that recomputes what depends on the state after it was written: (model, data)
Forward = Callable[[Any, Any], None]


def step_function(convention: str, mujoco: Any) -> Step:
    """The convention's physics step, MuJoCo's functions bound once (it runs every env step)."""
    if convention == "dm_control":
        step, step1, step2, rk4 = mujoco.mj_step, mujoco.mj_step1, mujoco.mj_step2, int(mujoco.mjtIntegrator.mjINT_RK4)

        def legacy_step(model: Any, data: Any, nstep: int) -> None:
            # mj_step1 ran after the last step (or the reset's forward): finish that step first
            if model.opt.integrator != rk4:
                step2(model, data)
                if nstep > 1:
                    step(model, data, nstep=nstep - 1)
            else:
                step(model, data, nstep=nstep)
            step1(model, data)

        return legacy_step
    step, post = mujoco.mj_step, mujoco.mj_rnePostConstraint

    def gymnasium_step(model: Any, data: Any, nstep: int) -> None:
        step(model, data, nstep=nstep)
        post(model, data)

    return gymnasium_step


def forward_function(convention: str, mujoco: Any) -> Forward:
    """The forward pass after a reset's writes: ``mj_forward``, with actuation disabled for dm_control (its ``after_reset``)."""
    if convention != "dm_control":
        return mujoco.mj_forward
    forward, actuation = mujoco.mj_forward, int(mujoco.mjtDisableBit.mjDSBL_ACTUATION)

    def forward_without_actuation(model: Any, data: Any) -> None:
        flags = model.opt.disableflags
        model.opt.disableflags = flags | actuation
        try:
            forward(model, data)
        finally:
            model.opt.disableflags = flags

    return forward_without_actuation


def reset_data(convention: str, mujoco: Any, model: Any, data: Any, keyframe: int | None) -> None:
    """MuJoCo's reset (to the model's qpos0, or a keyframe), and dm_control's forward after it."""
    if keyframe is None:
        mujoco.mj_resetData(model, data)
    else:
        mujoco.mj_resetDataKeyframe(model, data, keyframe)
    if convention == "dm_control":
        forward_function(convention, mujoco)(model, data)


def legacy_stream(seed: int | None, fallback: np.random.Generator) -> np.random.RandomState:
    """dm_control's task stream for ``reset(seed=seed)``: ``RandomState(seed)``; without a seed, one drawn from `fallback`.

    (`fallback` is the env's Gymnasium generator, itself seeded from the OS when no seed was ever
    given, so an unseeded env still differs from run to run, and a pickled one carries both.)
    A seed of 2**32 or more, which dm_control's RandomState cannot take (evaluation seeds can be
    that large), seeds the stream from its 32-bit words instead: the same seed, the same stream.
    """
    if seed is None:
        seed = int(fallback.integers(LEGACY_SEED_LIMIT))
    if seed < LEGACY_SEED_LIMIT:
        return np.random.RandomState(seed)
    words = []
    while seed:
        words.append(seed % LEGACY_SEED_LIMIT)
        seed //= LEGACY_SEED_LIMIT
    return np.random.RandomState(np.array(words, dtype=np.uint32))
