"""What physics.look 'mujoco' costs against 'physical', one render against the other, in one process.

The 2-core machine these figures come from is shared and its load swings a
step's time by a factor of two between runs, so the two looks are measured
interleaved: two envs of the same spec (one per look) step in turn, and each
render call's wall and CPU time (every thread of the process: Cycles' own)
is recorded. CPU time barely depends on the other processes' load.

    python benchmarks/mujoco_look_cost.py specs/mujoco/half_cheetah.yaml specs/dmc/cartpole_swingup.yaml --steps 300
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

import visualenv


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


def measure(spec: Path, steps: int) -> dict[str, tuple[float, float]]:
    """Median wall and CPU milliseconds of a step (its render) for each look, the envs stepped in turn."""
    with tempfile.TemporaryDirectory() as folder:
        envs = {look: visualenv.make(spec_with_look(spec, look, Path(folder))) for look in ("mujoco", "physical")}
        try:
            times: dict[str, list[tuple[float, float]]] = {look: [] for look in envs}
            for env in envs.values():
                env.reset(seed=0)
            rng = np.random.default_rng(0)
            for i in range(steps + 20):
                action = None
                for look, env in envs.items():
                    if action is None:
                        action = rng.uniform(env.action_space.low, env.action_space.high).astype(env.action_space.dtype)
                    wall, cpu = time.perf_counter(), time.process_time()
                    _, _, terminated, truncated, _ = env.step(action)
                    if i >= 20:  # after a warm-up
                        times[look].append((time.perf_counter() - wall, time.process_time() - cpu))
                    if terminated or truncated:
                        env.reset()
            return {look: (1e3 * float(np.median([w for w, _ in t])), 1e3 * float(np.median([c for _, c in t]))) for look, t in times.items()}
        finally:
            for env in envs.values():
                env.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("specs", nargs="+", type=Path)
    parser.add_argument("--steps", type=int, default=300)
    args = parser.parse_args()
    for spec in args.specs:
        result = measure(spec, args.steps)
        (mw, mc), (pw, pc) = result["mujoco"], result["physical"]
        print(f"{spec}: a step, median of {args.steps}: mujoco {mw:.2f} ms wall, {mc:.2f} ms CPU; "
              f"physical {pw:.2f} ms wall, {pc:.2f} ms CPU; mujoco / physical CPU {mc / pc:.2f}")


if __name__ == "__main__":
    main()
