"""A state-only physics batch's memory: the process's peak resident set after a reset and a few steps.

    python benchmarks/physics_memory.py specs/dmc/cartpole_swingup.yaml 256     # SPEC N

Each env holds its own MjModel (its reset may write the model) and MjData; run from another checkout with
`PYTHONPATH` pointing at it for a before/after comparison.
"""

import resource
import sys

from visualenv.env.batch import BatchedVectorEnv

spec, n = sys.argv[1], int(sys.argv[2])
batch = BatchedVectorEnv(spec, n, render=False)
batch.reset(seed=0)
for _ in range(5):
    batch.step(batch.action_space.sample())
model = batch.lanes[0].simulation.model
print(f"{spec}, N = {n}: peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024} MB; "
      f"an env's model holds {model.ntexdata / 1e6:.1f} MB of textures")
batch.close()
