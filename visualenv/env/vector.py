"""Parallel envs as Gymnasium vector envs: one Blender per worker process.

bpy holds one Blender per process, so parallel rendering needs processes:
:func:`make_vec` gives a Gymnasium ``AsyncVectorEnv`` (SB3's ``SubprocVecEnv``
is in :mod:`visualenv.env.sb3_vec`). Each worker builds its env (and its renderer)
from the spec, with ``threads`` render threads: with C cores usable by this
process (its affinity mask, not the machine's count) and N workers, each worker
is confined to its own C/N cores before Blender starts and renders with that many
threads (see :mod:`visualenv.env.cores`); ``pin=False`` leaves them unconfined.
"""

from __future__ import annotations

import multiprocessing
import signal
import sys
import time
from functools import partial
from typing import Any, Callable

import gymnasium as gym
from gymnasium.vector.async_vector_env import AsyncState, AsyncVectorEnv

from visualenv.compat.glibc import apply_policy
from visualenv.env.cores import Share, confine, render_threads, worker_cores
from visualenv.errors import WorkerError

_BROKEN = (EOFError, BrokenPipeError, ConnectionResetError)


def env_factory(
    target: str, *, cores: Share | None = None, wrapper_class: Callable[[gym.Env], gym.Env] | None = None, **kwargs: Any
) -> Callable[[], gym.Env]:
    """A picklable function that makes one env (for vector env workers), confined to `cores` if given.

    `wrapper_class` (a class or module-level function, so that it pickles) wraps the env in its worker.
    """
    return partial(make_in_worker, str(target), kwargs, cores, wrapper_class)


def make_in_worker(
    target: str,
    kwargs: dict[str, Any],
    cores: Share | None = None,
    wrapper_class: Callable[[gym.Env], gym.Env] | None = None,
) -> gym.Env:
    """One env made by :func:`visualenv.make`; in a worker process, confined to `cores` and deaf to Ctrl-C."""
    # in a worker (Gymnasium also calls this in the parent, for the spaces)
    if multiprocessing.parent_process() is not None:
        apply_policy()  # a process visualenv started: freed memory kept for the next render call
        if cores is not None:
            confine(cores)
        # Ctrl-C reaches the whole process group, and the parent decides how to stop.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    from visualenv.env.make import make

    env = make(target, **kwargs)
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

    def close_extras(self, timeout: float | None = None, terminate: bool = False, **kwargs: Any) -> None:
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


def with_render_threads(kwargs: dict[str, Any], share: Share | None, n: int, threads: int | None) -> dict[str, Any]:
    """A worker's make() options with its render threads: its share of the cores unless told otherwise (state-only envs need none)."""
    if kwargs.get("render") is False or "threads" in kwargs:
        return kwargs
    return {**kwargs, "threads": render_threads(share, n, threads)}


def warn_gpu_workers(target: str, n: int, kwargs: dict[str, Any]) -> None:
    """Once per process: several per-process envs rendering on one GPU share it badly, far below as many CPU workers
    (results/benchmarks/which-device.md)."""
    global _warned_gpu
    if _warned_gpu or n < 2 or kwargs.get("render") is False:
        return
    device = kwargs.get("device")
    if device is None:
        from visualenv.env.registration import resolve
        from visualenv.spec.loader import load_spec

        try:
            device = load_spec(resolve(target)).spec.render.device
        except Exception:  # noqa: BLE001 - a bad spec is reported by the workers, with its location
            return
    if device == "gpu":
        _warned_gpu = True
        print(
            f"visualenv: {n} envs with render.device 'gpu', one Blender process each, share the GPU badly "
            "(several Blender processes on one GPU step slower than as many CPU workers): one worker per core on the CPU is "
            "faster today; "
            "see docs/performance.md#which-device",
            file=sys.stderr,
            flush=True,
        )


_warned_gpu = False


def make_vec(
    target: str,
    n: int,
    *,
    asynchronous: bool = True,
    threads: int | None = None,
    pin: bool = True,
    wrapper_class: Callable[[gym.Env], gym.Env] | None = None,
    batched: bool = False,
    workers: int | None = None,
    **kwargs: Any,
) -> gym.vector.VectorEnv:
    """`n` copies of an env as a Gymnasium vector env (AsyncVectorEnv: one process each).

    Each worker is confined to its own share of the cores and renders with that many threads
    (`pin`; `threads` sets the render threads instead). `wrapper_class` wraps each env in its
    worker (as in SB3's ``make_vec_env``); kwargs go to :func:`visualenv.make` (render, frame_stack, params, ...).

    ``batched=True`` gives a :class:`~visualenv.env.batch.BatchedVectorEnv` instead: all `n` envs in
    this process and one Blender scene, one render call per step (kwargs: render, params,
    autoreset_mode, render_mode and the renderer options; stack frames with SB3's VecFrameStack).
    With ``workers=K`` as well, K processes each hold a batch of about n / K envs, each confined to its
    share of the cores (:class:`~visualenv.env.batch_workers.MultiBatchVectorEnv`), still one vector env of `n` envs.
    ``trust_code=True`` (the consent to import a spec's ``dynamics.python``) reaches every worker with the other kwargs.
    """
    if workers is not None and not batched:
        raise ValueError(
            "workers= splits a batch among processes: it goes with batched=True (without it, each env has its own process)"
        )
    if batched:
        from visualenv.env.batch import make_batched

        per_env = sorted(k for k in ("frame_stack", "grayscale", "resize") if kwargs.get(k) not in (None, False))
        if per_env or wrapper_class is not None:
            raise ValueError(
                f"make_vec(batched=True) takes no per-env wrappers ({', '.join(per_env) or 'wrapper_class'}): "
                "wrap the vector env instead (SB3's VecFrameStack stacks frames; `visualenv train --batched` does)"
            )
        if workers is not None:
            from visualenv.env.batch_workers import MultiBatchVectorEnv

            return MultiBatchVectorEnv(target, n, workers, pin=pin, threads=threads, **kwargs)
        if threads is not None:
            kwargs["threads"] = threads
        return make_batched(target, n, **kwargs)
    if asynchronous and n > 1:
        warn_gpu_workers(target, n, kwargs)
        return WorkerVectorEnv(
            [
                env_factory(
                    target, cores=share, wrapper_class=wrapper_class, **with_render_threads(kwargs, share, n, threads)
                )
                for share in worker_cores(n, pin)
            ],
            context="spawn",
            shared_memory=True,
        )
    kwargs = with_render_threads(kwargs, None, n, threads)
    return gym.vector.SyncVectorEnv([env_factory(target, wrapper_class=wrapper_class, **kwargs) for _ in range(n)])
