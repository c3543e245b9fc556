"""Parallel envs: one Blender per worker process.

bpy holds one Blender per process, so parallel rendering needs processes:
:func:`make_vec` gives a Gymnasium ``AsyncVectorEnv`` and :func:`make_sb3_vec`
an SB3 ``SubprocVecEnv`` (with SB3's own ``VecFrameStack``). Each worker builds
its env (and its renderer) from the spec, with ``threads`` render threads: on a
machine with C cores and N workers, C // N threads each keeps the cores busy
without oversubscribing them.
"""

from __future__ import annotations

import os
import time
from functools import partial
from typing import Any, Callable

import gymnasium as gym
from gymnasium.vector.async_vector_env import AsyncState, AsyncVectorEnv

from visualenv.errors import WorkerError

_BROKEN = (EOFError, BrokenPipeError, ConnectionResetError)


def default_threads(n_envs: int) -> int:
    return max(1, (os.cpu_count() or 1) // max(1, n_envs))


def env_factory(target: str, **kwargs: Any) -> Callable[[], gym.Env]:
    """A picklable function that makes one env (for vector env workers)."""
    return partial(_make, str(target), kwargs)


def _make(target: str, kwargs: dict[str, Any]) -> gym.Env:
    import visualenv

    return visualenv.make(target, **kwargs)


class WorkerVectorEnv(AsyncVectorEnv):
    """AsyncVectorEnv that turns a dead worker into a clear :class:`WorkerError`.

    Gymnasium's own class surfaces a killed worker as a bare ``EOFError`` (or
    hangs in ``close``); here the error names the dead workers and their exit
    codes, and ``close()`` terminates whatever is left, so no Blender process
    outlives the vector env.
    """

    def reset_wait(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return super().reset_wait(*args, **kwargs)
        except _BROKEN:
            raise self._worker_error("reset") from None

    def step_wait(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return super().step_wait(*args, **kwargs)
        except _BROKEN:
            raise self._worker_error("step") from None

    def _worker_error(self, call: str) -> WorkerError:
        self._state = AsyncState.DEFAULT
        deadline = time.monotonic() + 2.0  # the pipe can break a moment before the process is reaped
        while all(p.is_alive() for p in self.processes) and time.monotonic() < deadline:
            time.sleep(0.02)
        dead = [f"#{i} (pid {p.pid}, exit code {p.exitcode})" for i, p in enumerate(self.processes) if not p.is_alive()]
        what = ", ".join(dead) or "a worker"
        return WorkerError(f"vector env worker {what} died during {call}(); close the vector env and make a new one")

    def close_extras(self, timeout: float | None = None, terminate: bool = False) -> None:
        if any(not p.is_alive() for p in self.processes):
            terminate = True
            self._state = AsyncState.DEFAULT
        try:
            super().close_extras(timeout=timeout, terminate=terminate)
        except _BROKEN:
            for process in self.processes:
                if process.is_alive():
                    process.terminate()
                process.join(timeout=5)


def _with_threads(kwargs: dict[str, Any], n: int, threads: int | None) -> dict[str, Any]:
    """Give rendering workers a share of the cores unless told otherwise (state-only envs need none)."""
    if kwargs.get("render") is not False:
        kwargs.setdefault("threads", threads or default_threads(n))
    return kwargs


def make_vec(target: str, n: int, *, asynchronous: bool = True, threads: int | None = None, **kwargs: Any) -> gym.vector.VectorEnv:
    """`n` copies of an env as a Gymnasium vector env (AsyncVectorEnv: one process each).

    kwargs go to :func:`visualenv.make` (render, frame_stack, params, ...).
    """
    kwargs = _with_threads(kwargs, n, threads)
    fns = [env_factory(target, **kwargs) for _ in range(n)]
    if asynchronous and n > 1:
        return WorkerVectorEnv(fns, context="spawn", shared_memory=True)
    return gym.vector.SyncVectorEnv(fns)


def make_sb3_vec(target: str, n: int, *, seed: int = 0, frame_stack: int = 4, threads: int | None = None,
                 monitor_dir: str | None = None, **kwargs: Any) -> Any:
    """`n` envs in SB3's ``SubprocVecEnv`` (``DummyVecEnv`` for one), frames stacked by ``VecFrameStack``."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecFrameStack

    kwargs = _with_threads(kwargs, n, threads)
    vec = make_vec_env(
        _make,
        n_envs=n,
        seed=seed,
        env_kwargs={"target": str(target), "kwargs": kwargs},
        vec_env_cls=SubprocVecEnv if n > 1 else DummyVecEnv,
        vec_env_kwargs={"start_method": "spawn"} if n > 1 else None,
        monitor_dir=monitor_dir,
    )
    if frame_stack and frame_stack > 1 and kwargs.get("render") is not False:
        vec = VecFrameStack(vec, n_stack=frame_stack)
    return vec
