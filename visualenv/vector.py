"""Parallel envs: one Blender per worker process.

bpy holds one Blender per process, so parallel rendering needs processes:
:func:`make_vec` gives a Gymnasium ``AsyncVectorEnv`` and :func:`make_sb3_vec`
an SB3 ``SubprocVecEnv`` (with SB3's own ``VecFrameStack``). Each worker builds
its env (and its renderer) from the spec, with ``threads`` render threads: with
C cores usable by this process (its affinity mask, not the machine's count) and
N workers, C // N threads each keeps the cores busy without oversubscribing them.

``pin=True`` pins worker i to core i (round robin over the cores this process
may use). A Blender render keeps more threads busy than its render threads: with
one render thread, Cycles' session thread traces while an idle thread of
Blender's pool spins on the other core. Pinning keeps that spinning off another
worker's core and cuts the workers' p99 render time by a third, but on the 2-core
development VM steps/s overlap from run to run (ten interleaved runs of two
CartPole workers: 493-600 steps/s pinned, 467-615 not;
``benchmarks/parallel_ceiling.py``, ``visualenv bench --pin``), and pinning would
crowd two jobs onto the same cores, so it is off by default.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import time
from functools import partial
from typing import Any, Callable

import gymnasium as gym
from gymnasium.vector.async_vector_env import AsyncState, AsyncVectorEnv

from visualenv.errors import WorkerError

_BROKEN = (EOFError, BrokenPipeError, ConnectionResetError)


def usable_cores() -> list[int]:
    """The cores this process may run on: its affinity mask, which a container, a batch
    scheduler or ``taskset`` may make smaller than the machine (``os.cpu_count()``)."""
    try:
        return sorted(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return list(range(os.cpu_count() or 1))


def default_threads(n_envs: int) -> int:
    """Render threads per worker that fill this process's cores without oversubscribing them."""
    return max(1, len(usable_cores()) // max(1, n_envs))


def worker_cores(n: int, pin: bool = True) -> list[int | None]:
    """The core each of `n` workers is pinned to: round robin over this process's cores (None: not pinned)."""
    if not pin or n < 2 or not hasattr(os, "sched_setaffinity"):
        return [None] * n
    cores = usable_cores()
    if len(cores) < 2:
        return [None] * n
    return [cores[i % len(cores)] for i in range(n)]


def _pin(core: int) -> None:
    """Pin every thread of this process to `core` (threads started later inherit it)."""
    try:
        threads = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]
    for tid in threads:
        with contextlib.suppress(OSError):
            os.sched_setaffinity(tid, {core})


def env_factory(target: str, *, core: int | None = None, wrapper_class: Callable[[gym.Env], gym.Env] | None = None,
                **kwargs: Any) -> Callable[[], gym.Env]:
    """A picklable function that makes one env (for vector env workers), pinned to `core` if given.

    `wrapper_class` (a class or module-level function, so that it pickles) wraps the env in its worker.
    """
    return partial(_make, str(target), kwargs, core, wrapper_class)


def _make(target: str, kwargs: dict[str, Any], core: int | None = None,
          wrapper_class: Callable[[gym.Env], gym.Env] | None = None) -> gym.Env:
    if multiprocessing.parent_process() is not None:  # in a worker (Gymnasium also calls this in the parent, for the spaces)
        if core is not None:
            _pin(core)
        # Ctrl-C reaches the whole process group, and the parent decides how to stop.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    import visualenv

    env = visualenv.make(target, **kwargs)
    return wrapper_class(env) if wrapper_class is not None else env


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


def make_vec(target: str, n: int, *, asynchronous: bool = True, threads: int | None = None, pin: bool = False,
             wrapper_class: Callable[[gym.Env], gym.Env] | None = None, **kwargs: Any) -> gym.vector.VectorEnv:
    """`n` copies of an env as a Gymnasium vector env (AsyncVectorEnv: one process each).

    `wrapper_class` wraps each env in its worker (as in SB3's ``make_vec_env``);
    kwargs go to :func:`visualenv.make` (render, frame_stack, params, ...).
    """
    kwargs = _with_threads(kwargs, n, threads)
    if asynchronous and n > 1:
        return WorkerVectorEnv([env_factory(target, core=core, wrapper_class=wrapper_class, **kwargs) for core in worker_cores(n, pin)],
                               context="spawn", shared_memory=True)
    return gym.vector.SyncVectorEnv([env_factory(target, wrapper_class=wrapper_class, **kwargs) for _ in range(n)])


def make_sb3_vec(target: str, n: int, *, seed: int = 0, frame_stack: int = 4, threads: int | None = None, pin: bool = False,
                 monitor_dir: str | None = None, monitor_append: bool = False, **kwargs: Any) -> Any:
    """`n` envs in SB3's ``SubprocVecEnv`` (``DummyVecEnv`` for one), frames stacked by ``VecFrameStack``.

    Like SB3's ``make_vec_env``: env ``i`` is seeded ``seed + i`` and wrapped in a
    ``Monitor`` writing ``monitor_dir/i.monitor.csv`` when a folder is given
    (appended to with ``monitor_append``, for a resumed run).
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecFrameStack

    kwargs = _with_threads(kwargs, n, threads)
    fns = [partial(_make_monitored, str(target), kwargs, core, seed + i, monitor_dir and os.path.join(monitor_dir, str(i)), monitor_append)
           for i, core in enumerate(worker_cores(n, pin))]
    if monitor_dir:
        os.makedirs(monitor_dir, exist_ok=True)
    vec = SubprocVecEnv(fns, start_method="spawn") if n > 1 else DummyVecEnv(fns)
    vec.seed(seed)
    if frame_stack and frame_stack > 1 and kwargs.get("render") is not False:
        vec = VecFrameStack(vec, n_stack=frame_stack)
    return vec


def _make_monitored(target: str, kwargs: dict[str, Any], core: int | None, seed: int, monitor_file: str | None,
                    append: bool = False) -> gym.Env:
    from stable_baselines3.common.monitor import Monitor

    env = _make(target, kwargs, core)
    env.action_space.seed(seed)
    return Monitor(env, filename=monitor_file, override_existing=not append)
