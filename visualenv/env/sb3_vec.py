"""Parallel envs for Stable-Baselines3: ``SubprocVecEnv`` workers, seeded and monitored like SB3's ``make_vec_env``."""

from __future__ import annotations

import os
from functools import partial
from typing import Any

import gymnasium as gym

from visualenv.env.cores import Share, worker_cores
from visualenv.env.vector import make_in_worker, warn_gpu_workers, with_render_threads


def make_sb3_vec(target: str, n: int, *, seed: int = 0, frame_stack: int = 4, threads: int | None = None, pin: bool = True,
                 monitor_dir: str | None = None, monitor_append: bool = False, **kwargs: Any) -> Any:
    """`n` envs in SB3's ``SubprocVecEnv`` (``DummyVecEnv`` for one), frames stacked by ``VecFrameStack``.

    Like SB3's ``make_vec_env``: env ``i`` is seeded ``seed + i`` and wrapped in a
    ``Monitor`` writing ``monitor_dir/i.monitor.csv`` when a folder is given
    (appended to with ``monitor_append``, for a resumed run). Each worker is confined to its own share
    of the cores (`pin`) and renders with that many threads unless `threads` says otherwise.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecFrameStack

    warn_gpu_workers(target, n, kwargs)
    fns = [partial(_make_monitored, str(target), with_render_threads(kwargs, share, n, threads), share, seed + i,
                   monitor_dir and os.path.join(monitor_dir, str(i)), monitor_append)
           for i, share in enumerate(worker_cores(n, pin))]
    if monitor_dir:
        os.makedirs(monitor_dir, exist_ok=True)
    vec: Any = SubprocVecEnv(fns, start_method="spawn") if n > 1 else DummyVecEnv(fns)  # type: ignore[arg-type]  # partials are env makers
    vec.seed(seed)
    if frame_stack and frame_stack > 1 and kwargs.get("render") is not False:
        vec = VecFrameStack(vec, n_stack=frame_stack)
    return vec


def _make_monitored(target: str, kwargs: dict[str, Any], cores: Share | None, seed: int, monitor_file: str | None,
                    append: bool = False) -> gym.Env:
    from stable_baselines3.common.monitor import Monitor

    env = make_in_worker(target, kwargs, cores)
    env.action_space.seed(seed)
    return Monitor(env, filename=monitor_file, override_existing=not append)


def make_sb3_batched(target: str, n: int, *, seed: int = 0, frame_stack: int = 4, threads: int | None = None,
                     monitor_dir: str | None = None, monitor_append: bool = False, **kwargs: Any) -> Any:
    """`n` envs in one process and one Blender (a :class:`BatchedVectorEnv`) as an SB3 VecEnv, frames stacked by ``VecFrameStack``.

    Env ``i`` is seeded ``seed + i``; ``VecMonitor`` writes ``monitor_dir/batch.monitor.csv``.
    """
    from stable_baselines3.common.vec_env import VecFrameStack, VecMonitor

    from visualenv.env.batched import BatchedVectorEnv

    own = {k: kwargs.pop(k) for k in ("render", "params") if k in kwargs}
    if threads is not None:
        kwargs["threads"] = threads
    vec: Any = SB3Batch(BatchedVectorEnv(target, n, autoreset_mode="same_step", renderer_options=kwargs, **own))
    vec.seed(seed)
    if monitor_dir:
        os.makedirs(monitor_dir, exist_ok=True)
    vec = VecMonitor(vec, filename=os.path.join(monitor_dir, "batch") if monitor_dir else None)
    if monitor_append and monitor_dir:
        pass  # VecMonitor starts a new file; the resumed run's earlier episodes stay in the folder's other files
    if frame_stack and frame_stack > 1 and own.get("render") is not False:
        vec = VecFrameStack(vec, n_stack=frame_stack)
    return vec


def _sb3_vec_env() -> type:
    from stable_baselines3.common.vec_env import VecEnv

    return VecEnv


class SB3Batch(_sb3_vec_env()):  # type: ignore[misc]  # SB3 is imported here only, as the train extra provides it
    """SB3's VecEnv API over a :class:`BatchedVectorEnv` reset in the same step (``terminal_observation`` in infos)."""

    def __init__(self, batch: Any) -> None:
        import numpy as np

        self.batch = batch
        self._np = np
        self._seeds: list[int | None] = [None] * batch.num_envs
        self._actions: Any = None
        super().__init__(batch.num_envs, batch.single_observation_space, batch.single_action_space)

    def reset(self) -> Any:
        seeds = self._seeds if any(s is not None for s in self._seeds) else None
        obs, _ = self.batch.reset(seed=seeds)
        self._seeds = [None] * self.num_envs
        return obs

    def step_async(self, actions: Any) -> None:
        self._actions = actions

    def step_wait(self) -> Any:
        obs, rewards, terminated, truncated, info = self.batch.step(self._actions)
        dones = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i in range(self.num_envs):
            infos[i]["is_success"] = bool(info["is_success"][i])
            infos[i]["outcome"] = info["outcome"][i]
            if dones[i]:
                final = info["final_info"]
                infos[i]["is_success"] = bool(final["is_success"][i])
                infos[i]["outcome"] = final["outcome"][i]
                infos[i]["terminal_observation"] = info["final_obs"][i]
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, rewards.astype(self._np.float32), dones, infos

    def seed(self, seed: int | None = None) -> list[int | None]:
        self._seeds = [None if seed is None else seed + i for i in range(self.num_envs)]
        return self._seeds

    def close(self) -> None:
        self.batch.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.batch.lanes[i], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        for i in self._get_indices(indices):
            setattr(self.batch.lanes[i], attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        return [getattr(self.batch.lanes[i], method_name)(*method_args, **method_kwargs) for i in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]
