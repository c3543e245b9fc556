"""What one update of `train --algo sac --augment shift` costs, by encoder and batch size: SB3's NatureCNN (the DMC
preset's) against DrQ's own encoder (`visualenv.train.encoders.DrQEncoder`), on 3 stacked 84x84 RGB frames.

No env renders: the replay buffer is filled with random frames, and each figure is the median of `--updates` calls of
DrQ's SAC's ``train(gradient_steps=2)`` (the preset's schedule: the critic at each update, the actor at one of two),
halved, after one unmeasured call, the encoders alternated round by round.

    python benchmarks/drq_update.py --batch-sizes 128,512 --updates 10 --rounds 3 [--layouts]

`train` lays out the policy's convolutions channels-last (`visualenv.train.encoders.channels_last`); `--layouts` also
times each encoder with them contiguous (channel-first), as before it did, alternated in the same rounds.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
import yaml
from gymnasium import spaces

from visualenv.train.drq import model_arguments
from visualenv.train.encoders import channels_last
from visualenv.train.model_files import algorithm_class
from visualenv.train.sb3 import algorithm_kwargs

PRESET = Path(__file__).parents[1] / "examples/hyperparams/dmc_drq.yaml"
ENCODERS = {"NatureCNN": None, "DrQEncoder": "visualenv.train.encoders.DrQEncoder"}


class Frames(gym.Env):
    """3 stacked 84x84 RGB frames of noise, one action in [-1, 1]: the shapes of DMC cartpole's training."""

    observation_space = spaces.Box(0, 255, (84, 84, 9), np.uint8)
    action_space = spaces.Box(-1, 1, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, False, False, {}


def model(encoder: str | None, batch_size: int, layout: str = "channels-last"):
    preset = yaml.safe_load(PRESET.read_text())
    if encoder is not None:
        preset["policy_kwargs"] = {**preset["policy_kwargs"], "features_extractor_class": encoder}
    kwargs = algorithm_kwargs(
        "sac", {**preset, "buffer_size": 2 * batch_size, "learning_starts": 2 * batch_size - 1}, "shift"
    )
    policy, extra = model_arguments("sac", "shift", "CnnPolicy")
    sac = algorithm_class("sac", "shift")(
        policy, Frames(), seed=0, device="cpu", **{**kwargs, "batch_size": batch_size}, **extra
    )
    if layout == "channels-last":
        channels_last(sac.policy)  # as train's model
    sac.learn(2 * batch_size - 1)  # fills the buffer, no update yet
    return sac


def update_ms(sac, batch_size: int, updates: int) -> float:
    sac.train(gradient_steps=2, batch_size=batch_size)  # warm-up: allocations, oneDNN's first calls
    times = []
    for _ in range(updates):  # in pairs: DrQ's actor trains at one update of two (the preset's actor_update_interval)
        start = time.perf_counter()
        sac.train(gradient_steps=2, batch_size=batch_size)
        times.append((time.perf_counter() - start) / 2)
    return 1000 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch-sizes", default="128,512")
    parser.add_argument("--updates", type=int, default=10)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--layouts", action="store_true", help="also time contiguous (channel-first) convolutions")
    args = parser.parse_args()
    layouts = ("channels-last", "contiguous") if args.layouts else ("channels-last",)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    for batch_size in [int(b) for b in args.batch_sizes.split(",")]:
        models = {
            f"{name} {layout}": model(encoder, batch_size, layout)
            for name, encoder in ENCODERS.items()
            for layout in layouts
        }
        figures: dict[str, list[float]] = {name: [] for name in models}
        for _ in range(args.rounds):
            for name, sac in models.items():
                figures[name].append(update_ms(sac, batch_size, args.updates))
        for name, rounds in figures.items():
            print(f"batch {batch_size:4d}  {name:24s}  {' / '.join(f'{ms:7.1f}' for ms in rounds)} ms an update")


if __name__ == "__main__":
    main()
