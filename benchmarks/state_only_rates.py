"""State-only step rates of one env and of a batch, for before/after comparisons of the episode's step.

    python benchmarks/state_only_rates.py ROOT [ROOT ...] [--specs a.yaml,b.yaml] [--envs 256] [--rounds 5]

Each ROOT is a checkout of visualenv (its specs are read from it); each round runs every
root in a fresh process, alternated, so that roots are compared under the same load.
Rates are by the process's CPU time (the machine is shared: wall time counts the others'),
the best of 25 blocks of 2,000 steps (one env, ``render=False``, reset by hand at an
episode's end) or of 20 blocks of 30 steps (a batch of ``--envs``, ``render=False``,
NEXT_STEP autoreset), random actions drawn before timing.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

DEFAULT_SPECS = "specs/visual_cartpole.yaml,specs/lunar_landing.yaml,specs/mujoco/inverted_pendulum.yaml"


def measure(root: str, spec: str, envs: int) -> dict[str, int]:
    """In this process: one env's and one batch's best steps per second (env-steps per second for the batch)."""
    import warnings

    sys.path.insert(0, root)
    warnings.filterwarnings("ignore")
    from visualenv.env.batched import BatchedVectorEnv
    from visualenv.env.visual_env import VisualEnv

    env = VisualEnv(f"{root}/{spec}", render=False)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(2000)]
    single = 0.0
    for _ in range(25):
        start = time.process_time()
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        single = max(single, len(actions) / (time.process_time() - start))
    batch = BatchedVectorEnv(f"{root}/{spec}", envs, render=False)
    batch.reset(seed=0)
    batch.action_space.seed(0)
    batch_actions = [batch.action_space.sample() for _ in range(30)]
    batched = 0.0
    for _ in range(20):
        start = time.process_time()
        for action in batch_actions:
            batch.step(action)
        batched = max(batched, envs * len(batch_actions) / (time.process_time() - start))
    batch.close()
    return {"single": round(single), "batch": round(batched)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("roots", nargs="+")
    parser.add_argument("--specs", default=DEFAULT_SPECS)
    parser.add_argument("--envs", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.roots[0], args.child[0], int(args.child[1]))))
        return
    print(f"# steps/s by CPU time; single: one env; batch: {args.envs} envs (env-steps/s)")
    for spec in args.specs.split(","):
        for round_ in range(args.rounds):
            for root in args.roots:
                out = subprocess.run([sys.executable, __file__, root, "--child", spec, str(args.envs)],
                                     capture_output=True, text=True, check=True).stdout
                figures = json.loads(out)
                print(f"{spec:40s} round {round_}  {root:40s} single {figures['single']:8d}  batch {figures['batch']:8d}", flush=True)


if __name__ == "__main__":
    main()
