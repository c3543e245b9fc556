"""Memory of one process that makes, steps and closes envs round after round (notebooks, sweeps).

    python benchmarks/env_rounds.py [batch|mixed] [ROUNDS]

batch: each round makes a 16-env Goalie batch (100x100), resets it, steps it once and closes it.
mixed: each round does that, then a Goalie env with its 400x400 view rendered, then a LunarLanding env.
Prints the resident memory after each round and the growth from the end of the second round
(the first two load what every later one shares), and the datablock count before and after.
"""

import gc
import sys
from pathlib import Path

import bpy
import psutil

from visualenv.env.batch import BatchedVectorEnv
from visualenv.env.visual_env import VisualEnv
from visualenv.render.blender.scene.build import ID_COLLECTIONS

SPECS = Path(__file__).parents[1] / "specs"
mode = sys.argv[1] if len(sys.argv) > 1 else "batch"
rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 20
process = psutil.Process()


def datablocks() -> int:
    return sum(len(getattr(bpy.data, name)) for name in ID_COLLECTIONS if hasattr(bpy.data, name))


def one_round(seed: int) -> None:
    batch = BatchedVectorEnv(SPECS / "goalie.yaml", 16)
    batch.reset(seed=seed)
    batch.step(batch.action_space.sample())
    batch.close()
    if mode == "mixed":
        env = VisualEnv(SPECS / "goalie.yaml", render_mode="rgb_array")
        env.reset(seed=seed)
        env.step(env.action_space.sample())
        env.render()
        env.close()
        env = VisualEnv(SPECS / "lunar_landing.yaml")
        env.reset(seed=seed)
        env.step(env.action_space.sample())
        env.close()
    gc.collect()


ids = datablocks()
rss = []
for seed in range(rounds):
    one_round(seed)
    rss.append(process.memory_info().rss / 2**20)
    print(f"round {seed + 1:>3}  RSS {rss[-1]:7.1f} MB  datablocks {datablocks()}", flush=True)
base = rss[1] if rounds > 2 else rss[0]
per_round = (rss[-1] - base) / max(1, rounds - 2)
print(f"{mode}: {rounds} rounds, RSS {base:.1f} MB after round 2, {rss[-1]:.1f} MB after round {rounds} "
      f"({rss[-1] - base:+.1f} MB, {per_round:+.2f} MB a round); datablocks {ids} before, {datablocks()} after")
