"""`visualenv bench-rllib`: env steps/s through RLlib's EnvRunners against SB3's SubprocVecEnv, in one run.

Both sides step the same spec with the same number of envs (one per process:
one EnvRunner of one env each, or one SubprocVecEnv worker each), four stacked
frames, random actions. RLlib's runners sample independently (each runner steps
its own envs and returns a batch), SubprocVecEnv steps all workers in lock-step.
Also printed: RLlib sampling through the policy (CNN inference on the runner's
CPU), resident memory per runner, and the time from the command's start to the
first sample (Ray start, runner actors, Blender scene, first render).

Figures vary from run to run on a shared machine: this prints, it asserts nothing.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import psutil


@dataclass
class RLlibFigures:
    spec: str
    envs: int
    steps_per_env: int
    sb3_steps_per_s: float = 0.0
    rllib_steps_per_s: float = 0.0
    rllib_policy_steps_per_s: float = 0.0
    ratio: float = 0.0
    seconds_to_first_sample: float = 0.0
    runner_rss_mb: list[float] | None = None
    sb3_worker_rss_mb: list[float] | None = None

    def lines(self) -> list[str]:
        rss = self.runner_rss_mb or []
        sb3 = self.sb3_worker_rss_mb or []
        return [
            f"{self.spec}: {self.envs} envs (one process each), {self.steps_per_env} measured steps per env, random actions, 4 stacked frames",
            f"  SB3 SubprocVecEnv          {self.sb3_steps_per_s:8.1f} env steps/s",
            f"  RLlib EnvRunners           {self.rllib_steps_per_s:8.1f} env steps/s  ({self.ratio:.2f}x SubprocVecEnv)",
            f"  RLlib, actions from PPO    {self.rllib_policy_steps_per_s:8.1f} env steps/s  (CNN inference in the runners)",
            f"  command to first sample    {self.seconds_to_first_sample:8.1f} s      (Ray start, runners, Blender scenes, first renders)",
            f"  resident memory per runner {np.mean(rss) if rss else 0:8.0f} MB     ({', '.join(f'{r:.0f}' for r in rss)}; "
            f"SB3 worker: {', '.join(f'{r:.0f}' for r in sb3)} MB)",
        ]


def _sb3_steps_per_s(
    spec: str, envs: int, steps: int, warmup: int, trust_code: bool = False
) -> tuple[float, list[float]]:
    from visualenv.env.sb3_vec import make_sb3_vec

    options: dict[str, Any] = {"trust_code": True} if trust_code else {}
    vec = make_sb3_vec(spec, envs, frame_stack=4, **options)
    try:
        vec.reset()
        rng = np.random.default_rng(0)
        n = vec.action_space.n

        def run(k: int) -> None:
            for _ in range(k):
                vec.step(rng.integers(0, n, size=envs))

        run(warmup)
        start = time.perf_counter()
        run(steps)
        seconds = time.perf_counter() - start
        workers = [p for p in psutil.Process().children() if p.is_running()]
        rss = [p.memory_info().rss / 2**20 for p in workers[-envs:]]
    finally:
        vec.close()
    return steps * envs / seconds, rss


def _rllib_steps_per_s(runners: Any, steps: int, random_actions: bool) -> float:
    start = time.perf_counter()
    sampled = runners.foreach_env_runner(
        lambda r: sum(len(e) for e in r.sample(num_timesteps=steps, random_actions=random_actions)),
        local_env_runner=False,
    )
    return sum(sampled) / (time.perf_counter() - start)


def bench_rllib(spec: str, envs: int = 2, steps: int = 200, warmup: int = 20, trust_code: bool = False) -> RLlibFigures:
    """RLlib first (its time to first sample counts from this process's start), then SB3. `trust_code`: the spec's
    ``dynamics.python`` may be imported, in the runners and SB3's workers too (docs/security.md)."""
    import ray

    from visualenv.train.rllib_setup import ppo_config

    figures = RLlibFigures(spec=spec, envs=envs, steps_per_env=steps)
    process_start = psutil.Process().create_time()
    ray.init(
        address="local",
        num_cpus=max(envs, len(os.sched_getaffinity(0))),
        include_dashboard=False,
        log_to_driver=False,
        logging_level=logging.ERROR,
    )
    try:
        algo = ppo_config(spec, env_runners=envs, envs_per_runner=1, trust_code=trust_code).build_algo()
        try:
            runners = algo.env_runner_group
            runners.foreach_env_runner(
                lambda r: len(r.sample(num_timesteps=1, random_actions=True)), local_env_runner=False
            )
            figures.seconds_to_first_sample = time.time() - process_start
            runners.foreach_env_runner(
                lambda r: len(r.sample(num_timesteps=warmup, random_actions=True)), local_env_runner=False
            )
            figures.rllib_steps_per_s = _rllib_steps_per_s(runners, steps, random_actions=True)
            figures.rllib_policy_steps_per_s = _rllib_steps_per_s(runners, steps, random_actions=False)
            figures.runner_rss_mb = runners.foreach_env_runner(
                lambda r: psutil.Process().memory_info().rss / 2**20, local_env_runner=False
            )
        finally:
            algo.stop()
    finally:
        ray.shutdown()
    figures.sb3_steps_per_s, figures.sb3_worker_rss_mb = _sb3_steps_per_s(spec, envs, steps, warmup, trust_code)
    figures.ratio = figures.rllib_steps_per_s / figures.sb3_steps_per_s if figures.sb3_steps_per_s else 0.0
    return figures


def as_dict(figures: RLlibFigures) -> dict[str, Any]:
    return asdict(figures)
