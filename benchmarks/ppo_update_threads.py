"""How long one PPO update of SB3's CnnPolicy takes on 1 thread and on every core, with its convolutions in torch's
default layout and channels-last (as `visualenv train` lays them out: `visualenv.train.encoders.channels_last`).

    .venv/bin/python benchmarks/ppo_update_threads.py [repeats]

One update of the bundled hyperparameters (examples/hyperparams/: 512 samples,
batch 128, 4 epochs) is 16 gradient steps on 128 stacked 4x100x100 frames.
`visualenv train` runs torch on one thread while the Blender workers render
and on every core during the update; this prints what the second half saves, and what the layout saves (the
layouts alternate within each repeat).
"""

from __future__ import annotations

import os
import sys
import time

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticCnnPolicy


def seconds_per_update(policy: ActorCriticCnnPolicy, threads: int, steps: int = 16, batch: int = 128) -> float:
    torch.set_num_threads(threads)
    frames = torch.randint(0, 255, (batch, 4, 100, 100), dtype=torch.uint8).float()
    actions = torch.randint(0, 4, (batch,))
    started = time.perf_counter()
    for _ in range(steps):
        values, log_prob, _ = policy.evaluate_actions(frames, actions)
        loss = -log_prob.mean() + values.pow(2).mean()
        policy.optimizer.zero_grad()
        loss.backward()
        policy.optimizer.step()
    return time.perf_counter() - started


def main() -> None:
    repeats = int(sys.argv[1]) if len(sys.argv) > 1 else 2
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    from visualenv.train.encoders import channels_last

    def policy() -> ActorCriticCnnPolicy:
        torch.manual_seed(0)
        space = gym.spaces.Box(0, 255, (4, 100, 100), np.uint8)
        return ActorCriticCnnPolicy(space, gym.spaces.Discrete(4), lambda _: 2.5e-4)

    policies = {"contiguous": policy(), "channels-last": channels_last(policy())}
    for _ in range(repeats):
        for threads in sorted({1, cores}):
            for layout, chosen in policies.items():
                seconds = seconds_per_update(chosen, threads)
                print(f"{threads} thread(s), {layout}: {seconds:.2f} s per update", flush=True)


if __name__ == "__main__":
    main()
