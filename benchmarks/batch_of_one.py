"""A batch of one against one env: env-steps/s of ``make_vec(ID, 1, batched=True)`` and of ``make(ID)``, and of two
envs made in one process and stepped in turn (as gymnasium's SyncVectorEnv and SB3's DummyVecEnv step theirs).

    python benchmarks/batch_of_one.py [ID ...] [--rounds 3] [--steps 380]

Each figure is its own process, the kinds alternated in each round, over the same seeded random actions after 20
untimed steps. For a before/after, run the script from each tree in turn (a ``git worktree`` of the commit before,
the same venv).
"""

from __future__ import annotations

import argparse
import subprocess
import sys

MEASURE = """
import sys, time, visualenv
ident, kind, steps = sys.argv[1], sys.argv[2], int(sys.argv[3])
if kind == "batch":
    envs = [visualenv.make_vec(ident, 1, batched=True)]
else:
    envs = [visualenv.make(ident) for _ in range(2 if kind == "in turn" else 1)]
for k, env in enumerate(envs):
    env.reset(seed=k)
envs[0].action_space.seed(0)
actions = [envs[0].action_space.sample() for _ in range(steps + 20)]
for k, action in enumerate(actions):
    if k == 20:
        start = time.perf_counter()
    for env in envs:
        out = env.step(action)
        if kind != "batch" and (out[2] or out[3]):
            env.reset()
print(steps * len(envs) / (time.perf_counter() - start))
for env in envs:
    env.close()
"""


def rate(ident: str, kind: str, steps: int) -> float:
    """Env-steps/s of one kind ("batch", "single" or "in turn"), measured in a process of its own."""
    done = subprocess.run(
        [sys.executable, "-c", MEASURE, ident, kind, str(steps)], capture_output=True, text=True, check=True
    )
    return float(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "ids", nargs="*", default=["DMC-cheetah-run-v0", "DMC-walker-walk-v0", "DMC-cartpole-swingup-v0"]
    )
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=380)
    args = parser.parse_args()
    for r in range(args.rounds):
        for ident in args.ids:
            figures = {kind: rate(ident, kind, args.steps) for kind in ("batch", "single", "in turn")}
            print(
                f"round {r + 1}  {ident:28s} batch of one {figures['batch']:6.1f}  one env {figures['single']:6.1f}  "
                f"two envs in turn {figures['in turn']:6.1f}  (env-steps/s)",
                flush=True,
            )


if __name__ == "__main__":
    main()
