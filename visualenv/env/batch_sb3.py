"""SB3's VecEnv API over a :class:`~visualenv.env.batch.BatchedVectorEnv`, or several (MultiBatchVectorEnv) (imports Stable-Baselines3: the train extra)."""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from visualenv.compat.sb3 import vec_env_indices


class SB3Batch(VecEnv):
    """SB3's VecEnv API over a :class:`BatchedVectorEnv` reset in the same step (``terminal_observation`` in infos)."""

    def __init__(self, batch: Any) -> None:
        self.batch = batch
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
        return obs, rewards.astype(np.float32), dones, infos

    def seed(self, seed: int | None = None) -> list[int | None]:
        self._seeds = [None if seed is None else seed + i for i in range(self.num_envs)]
        return self._seeds

    def close(self) -> None:
        self.batch.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        # batches in worker processes (MultiBatchVectorEnv): their lanes answer there
        if not hasattr(self.batch, "lanes"):
            values = self.batch.get_attr(attr_name)
            return [values[i] for i in vec_env_indices(self, indices)]
        return [getattr(self.batch.lanes[i], attr_name) for i in vec_env_indices(self, indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        if not hasattr(self.batch, "lanes"):
            raise NotImplementedError("set_attr on batches in worker processes: set it in the spec's params instead")
        for i in vec_env_indices(self, indices):
            setattr(self.batch.lanes[i], attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        if not hasattr(self.batch, "lanes"):
            values = self.batch.call(method_name, *method_args, **method_kwargs)
            return [values[i] for i in vec_env_indices(self, indices)]
        lanes = [self.batch.lanes[i] for i in vec_env_indices(self, indices)]
        return [getattr(lane, method_name)(*method_args, **method_kwargs) for lane in lanes]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in vec_env_indices(self, indices)]
