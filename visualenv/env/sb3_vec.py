"""Parallel envs for Stable-Baselines3: ``SubprocVecEnv`` workers, seeded and monitored like SB3's ``make_vec_env``."""

from __future__ import annotations

import os
from functools import partial
from typing import Any

import gymnasium as gym

from visualenv.env.cores import Share, worker_cores
from visualenv.env.vector import make_in_worker, warn_gpu_workers, with_render_threads


def make_sb3_vec(
    target: str,
    n: int,
    *,
    seed: int = 0,
    frame_stack: int = 4,
    threads: int | None = None,
    pin: bool = True,
    monitor_dir: str | None = None,
    monitor_append: bool = False,
    **kwargs: Any,
) -> Any:
    """`n` envs in SB3's ``SubprocVecEnv`` (``DummyVecEnv`` for one), frames stacked by ``VecFrameStack``.

    Like SB3's ``make_vec_env``: env ``i`` is seeded ``seed + i`` and wrapped in a
    ``Monitor`` writing ``monitor_dir/i.monitor.csv`` when a folder is given
    (appended to with ``monitor_append``, for a resumed run). Each worker is confined to its own share
    of the cores (`pin`) and renders with that many threads unless `threads` says otherwise.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecFrameStack

    warn_gpu_workers(target, n, kwargs)
    fns = [
        partial(
            _make_monitored,
            str(target),
            with_render_threads(kwargs, share, n, threads),
            share,
            seed + i,
            monitor_dir and os.path.join(monitor_dir, str(i)),
            monitor_append,
        )
        for i, share in enumerate(worker_cores(n, pin))
    ]
    if monitor_dir:
        os.makedirs(monitor_dir, exist_ok=True)
    vec: Any = SubprocVecEnv(fns, start_method="spawn") if n > 1 else DummyVecEnv(fns)  # type: ignore[arg-type]  # partials are env makers
    vec.seed(seed)
    if frame_stack and frame_stack > 1 and kwargs.get("render") is not False:
        vec = VecFrameStack(vec, n_stack=frame_stack)
    return vec


def _env_id(target: str) -> str:
    """The id a monitor file names, as ``gymnasium.make`` knows the env (``visualenv/<spec id>``), as SB3's Monitor writes it."""
    from visualenv.env.registration import NAMESPACE, read_header, resolve

    spec_id = read_header(resolve(target))[0]
    return f"{NAMESPACE}/{spec_id}" if spec_id else str(target)


def _make_monitored(
    target: str, kwargs: dict[str, Any], cores: Share | None, seed: int, monitor_file: str | None, append: bool = False
) -> gym.Env:
    from stable_baselines3.common.monitor import Monitor

    env = make_in_worker(target, kwargs, cores)
    env.action_space.seed(seed)
    return Monitor(env, filename=monitor_file, override_existing=not append)


def make_sb3_batched(
    target: str,
    n: int,
    *,
    seed: int = 0,
    frame_stack: int = 4,
    threads: int | None = None,
    monitor_dir: str | None = None,
    monitor_append: bool = False,
    workers: int | None = None,
    pin: bool = True,
    **kwargs: Any,
) -> Any:
    """`n` envs in one process and one Blender (a :class:`BatchedVectorEnv`) as an SB3 VecEnv, frames stacked by ``VecFrameStack``.

    Env ``i`` is seeded ``seed + i``; ``VecMonitor`` writes ``monitor_dir/batch.monitor.csv``
    (appended to with ``monitor_append``, for a resumed run). ``workers=K``: K processes each hold a batch of
    about n / K envs, confined to their share of the cores (`pin`).
    """
    from stable_baselines3.common.monitor import ResultsWriter
    from stable_baselines3.common.vec_env import VecFrameStack, VecMonitor

    from visualenv.env.batch import make_batched
    from visualenv.env.batch_sb3 import SB3Batch

    if workers is not None:
        from visualenv.env.batch_workers import MultiBatchVectorEnv

        batch: Any = MultiBatchVectorEnv(
            target, n, workers, pin=pin, threads=threads, autoreset_mode="same_step", **kwargs
        )
    else:
        if threads is not None:
            kwargs["threads"] = threads
        batch = make_batched(target, n, autoreset_mode="same_step", **kwargs)
    vec: Any = SB3Batch(batch)
    vec.seed(seed)
    vec = VecMonitor(vec)
    if monitor_dir:
        # VecMonitor's own writer always starts the file afresh: a resumed run would lose its earlier episodes
        vec.results_writer = ResultsWriter(
            os.path.join(monitor_dir, "batch"),
            header={"t_start": vec.t_start, "env_id": _env_id(target)},
            override_existing=not monitor_append,
        )
    if frame_stack and frame_stack > 1 and kwargs.get("render") is not False:
        vec = VecFrameStack(vec, n_stack=frame_stack)
    return vec
