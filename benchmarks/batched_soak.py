"""Memory of a batched env over many steps: RSS every tenth of the run (issue: no growth over 50,000 env-steps).

    python benchmarks/batched_soak.py [SPEC] [N] [ENV_STEPS]
"""

import sys

import psutil

from visualenv.env.batch import BatchedVectorEnv

spec = sys.argv[1] if len(sys.argv) > 1 else "specs/visual_cartpole.yaml"
n = int(sys.argv[2]) if len(sys.argv) > 2 else 16
total = int(sys.argv[3]) if len(sys.argv) > 3 else 50_000
env = BatchedVectorEnv(spec, n)
env.reset(seed=0)
env.action_space.seed(0)
process = psutil.Process()
rounds = total // n
marks = []
for i in range(rounds):
    env.step(env.action_space.sample())
    if i % max(1, rounds // 10) == 0 or i == rounds - 1:
        marks.append((i * n, process.memory_info().rss / 2**20))
        print(f"{i * n:>7} env-steps  RSS {marks[-1][1]:7.1f} MB", flush=True)
first = marks[1][1] if len(marks) > 1 else marks[0][1]
print(f"{spec}, {n} envs, {rounds * n} env-steps: RSS {first:.1f} MB after warm-up, {marks[-1][1]:.1f} MB at the end "
      f"({marks[-1][1] - first:+.1f} MB)")
env.close()
