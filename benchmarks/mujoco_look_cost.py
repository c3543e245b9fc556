"""What physics.look 'mujoco' costs against 'physical': a step's wall and CPU time, one env per process, alternated.

The 2-core machine these figures come from is shared and its load swings a
step's wall time by a factor of two between runs, so the two looks run in
turn, in rounds, each in a fresh process stepping one env; each step's CPU
time (every thread of the process: Cycles' own) is recorded beside its wall
time, CPU time depending less on the other processes' load. ``--interleaved``
instead steps one env of each look in one process, in turn: every render then
switches Blender's scene (a sync vector env's case), which Cycles' persistent
data does not survive.

    python benchmarks/mujoco_look_cost.py specs/mujoco/half_cheetah.yaml specs/dmc/cartpole_swingup.yaml --rounds 3
    python benchmarks/mujoco_look_cost.py specs/dmc/cartpole_swingup.yaml --interleaved
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

LOOKS = ("mujoco", "physical")


def spec_with_look(spec: Path, look: str, folder: Path) -> Path:
    """A copy of `spec` with physics.look set (its model path made absolute, so the copy lives elsewhere)."""
    data = yaml.safe_load(spec.read_text(encoding="utf-8"))
    model = data["physics"]["model"]
    if not str(model).startswith("package:"):
        data["physics"]["model"] = str((spec.parent / model).resolve())
    data["physics"]["look"] = look
    out = folder / f"{spec.stem}-{look}.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return out


def step_times(specs: list[Path], steps: int) -> list[list[tuple[float, float]]]:
    """(wall, CPU) seconds of each step after a warm-up, per spec, the specs' envs stepped in turn in this process."""
    import visualenv

    envs = [visualenv.make(spec) for spec in specs]
    try:
        for env in envs:
            env.reset(seed=0)
            env.action_space.seed(0)
        times: list[list[tuple[float, float]]] = [[] for _ in envs]
        for i in range(steps + 10):
            for env, record in zip(envs, times):
                action = env.action_space.sample()
                wall, cpu = time.perf_counter(), time.process_time()
                _, _, terminated, truncated, _ = env.step(action)
                if i >= 10:
                    record.append((time.perf_counter() - wall, time.process_time() - cpu))
                if terminated or truncated:
                    env.reset()
        return times
    finally:
        for env in envs:
            env.close()


def medians(times: list[tuple[float, float]]) -> tuple[float, float]:
    return 1e3 * float(np.median([w for w, _ in times])), 1e3 * float(np.median([c for _, c in times]))


def in_child(spec: Path, steps: int) -> tuple[float, float]:
    """Median wall and CPU ms of a step of one env of `spec`, in a fresh process."""
    done = subprocess.run([sys.executable, __file__, "--child", str(spec), "--steps", str(steps)], capture_output=True, text=True,
                          check=True, env={**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(Path(__file__).resolve().parent.parent),
                                                                                                    os.environ.get("PYTHONPATH")]))})
    wall, cpu = json.loads(done.stdout.strip().splitlines()[-1])
    return wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("specs", nargs="+", type=Path)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--interleaved", action="store_true", help="one env of each look in one process, stepped in turn")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:  # one env, this process: print its medians
        print(json.dumps(medians(step_times(args.specs, args.steps)[0])))
        return
    with tempfile.TemporaryDirectory() as folder:
        for spec in args.specs:
            copies = [spec_with_look(spec, look, Path(folder)) for look in LOOKS]
            if args.interleaved:
                results = {look: [medians(t)] for look, t in zip(LOOKS, step_times(copies, args.steps))}
            else:
                results = {look: [] for look in LOOKS}
                for _ in range(args.rounds):
                    for look, copy in zip(LOOKS, copies):
                        results[look].append(in_child(copy, args.steps))
            for look, runs in results.items():
                text = ", ".join(f"{w:.1f} ms wall / {c:.1f} ms CPU" for w, c in runs)
                load = os.getloadavg()[0]
                print(f"{spec} {look}: a step's median per run: {text} (load {load:.1f})")


if __name__ == "__main__":
    main()
