"""How a batch's tiles compare with each env rendered alone, where the scene has a light per env (a point, spot or area light).

    python benchmarks/batch_lighting.py specs/dmc/cartpole_swingup.yaml 8      # SPEC N [SEED]

Renders N envs batched and each alone from the same reset (env i seeded SEED + i, one env with its default noise as
`visualenv.make` gives it), and prints per tile the mean |difference| in levels and the share of pixels within 8
levels, then the worst tile and how many pixels differ by more than 8 in all. Run it from another checkout with
`PYTHONPATH` pointing at it for a before/after comparison.
"""

import sys

import numpy as np

from visualenv.env.batch import BatchedVectorEnv
from visualenv.env.visual_env import VisualEnv

spec, n = sys.argv[1], int(sys.argv[2])
seed = int(sys.argv[3]) if len(sys.argv) > 3 else 10
alone = []
for i in range(n):
    env = VisualEnv(spec)
    alone.append(env.reset(seed=seed + i)[0].astype(int))
    env.close()
batch = BatchedVectorEnv(spec, n)
try:
    tiles, _ = batch.reset(seed=seed)
finally:
    batch.close()
differences = [np.abs(tiles[i].astype(int) - alone[i]) for i in range(n)]
print(f"{spec}, N = {n}, seed {seed}")
print("mean |difference| per tile:", " ".join(f"{d.mean():.2f}" for d in differences))
print("share within 8 levels:     ", " ".join(f"{(d <= 8).mean():.3f}" for d in differences))
print(f"worst tile {max(d.mean() for d in differences):.2f} levels; pixels off by more than 8: "
      f"{sum(int((d > 8).any(axis=-1).sum()) for d in differences)} of {n * differences[0][..., 0].size}")
