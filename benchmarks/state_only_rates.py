"""State-only step rates of one env and of a batch, two checkouts compared in one process (before/after a change).

    python benchmarks/state_only_rates.py BEFORE_ROOT AFTER_ROOT [--specs a.yaml,b.yaml] [--envs 256] [--rounds 30]

Each ROOT is a checkout of visualenv (its package and its specs). Both packages are
imported into this process (one after the other, each keeping its own modules), and
their envs are stepped alternately, block by block: on a shared machine, whatever load
comes and goes falls on both alike. Rates are by the process's CPU time, the best
block of each: 2,000 steps of one env (``render=False``, reset by hand at an episode's
end) and 30 steps of a batch of ``--envs`` (``render=False``, NEXT_STEP autoreset), with
random actions drawn before timing.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
import warnings
from typing import Any

DEFAULT_SPECS = "specs/visual_cartpole.yaml,specs/lunar_landing.yaml,specs/mujoco/inverted_pendulum.yaml"


def import_package(root: str) -> tuple[Any, Any]:
    """BatchedVectorEnv and VisualEnv of the checkout at `root` (this process's other copy is set aside, not unloaded)."""
    for name in [n for n in sys.modules if n == "visualenv" or n.startswith("visualenv.")]:
        del sys.modules[name]
    sys.path.insert(0, root)
    try:
        batched = importlib.import_module("visualenv.env.batch")
        single = importlib.import_module("visualenv.env.visual_env")
    finally:
        sys.path.remove(root)
    return batched.BatchedVectorEnv, single.VisualEnv


def block_single(env: Any, actions: list) -> float:
    start = time.process_time()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.process_time() - start)


def block_batch(batch: Any, actions: list) -> float:
    start = time.process_time()
    for action in actions:
        batch.step(action)
    return batch.num_envs * len(actions) / (time.process_time() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("before")
    parser.add_argument("after")
    parser.add_argument("--specs", default=DEFAULT_SPECS)
    parser.add_argument("--envs", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=30)
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    classes = {"before": import_package(args.before), "after": import_package(args.after)}
    roots = {"before": args.before, "after": args.after}
    print(f"# steps/s by CPU time, best of {args.rounds} blocks each, alternated in one process; batch: {args.envs} envs (env-steps/s)")
    for spec in args.specs.split(","):
        runs: dict[str, tuple] = {}
        for key, (batch_class, env_class) in classes.items():
            env = env_class(f"{roots[key]}/{spec}", render=False)
            env.reset(seed=0)
            env.action_space.seed(0)
            batch = batch_class(f"{roots[key]}/{spec}", args.envs, render=False)
            batch.reset(seed=0)
            batch.action_space.seed(0)
            runs[key] = (env, [env.action_space.sample() for _ in range(2000)], batch, [batch.action_space.sample() for _ in range(30)])
        best = {key: [0.0, 0.0] for key in runs}
        for _ in range(args.rounds):
            for key, (env, env_actions, batch, batch_actions) in runs.items():
                best[key][0] = max(best[key][0], block_single(env, env_actions))
                best[key][1] = max(best[key][1], block_batch(batch, batch_actions))
        for run in runs.values():
            run[2].close()
        (single0, batch0), (single1, batch1) = best["before"], best["after"]
        print(f"{spec:38s} one env: {single0:9.0f} -> {single1:9.0f} ({100 * (single1 / single0 - 1):+5.1f} %)   "
              f"batch: {batch0:9.0f} -> {batch1:9.0f} ({100 * (batch1 / batch0 - 1):+5.1f} %)", flush=True)


if __name__ == "__main__":
    main()
