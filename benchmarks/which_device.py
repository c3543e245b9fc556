"""Which device: env steps/s of one env per engine and device, at 100x100 and 512x512 (VisualCartPole-v0).

Usage: python benchmarks/which_device.py [--spec VisualCartPole-v0] [--steps 200] [--slow-steps 3]

Rows: Cycles on the CPU, Cycles on the GPU (where Blender finds one), Workbench, EEVEE. EEVEE
without a GPU renders in software and takes seconds per frame, so it runs `--slow-steps` steps.
docs/performance.md#which-device has the figures of this machine and of an H100 machine.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from typing import Any

from visualenv.env.registration import resolve
from visualenv.env.visual_env import VisualEnv
from visualenv.spec.loader import load_spec


def with_resolution(loaded: Any, size: int) -> Any:
    observation = loaded.spec.observation.model_copy(update={"resolution": [size, size]})
    return replace(loaded, spec=loaded.spec.model_copy(update={"observation": observation}))


def steps_per_s(loaded: Any, steps: int, **options: Any) -> tuple[float, float]:
    """(steps/s after a warm-up of 3 steps, seconds to the first observation)."""
    started = time.perf_counter()
    env = VisualEnv(loaded, renderer_options=options)
    env.reset(seed=0)
    first = time.perf_counter() - started
    for i in range(3):
        env.step(i % 2)
    started = time.perf_counter()
    for i in range(steps):
        _, _, terminated, truncated, _ = env.step(i % 2)
        if terminated or truncated:
            env.reset()
    rate = steps / (time.perf_counter() - started)
    env.close()
    return rate, first


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spec", default="VisualCartPole-v0")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--slow-steps", type=int, default=3)
    args = parser.parse_args()
    from visualenv.render.blender.runtime.settings import detect_gpu

    gpu = detect_gpu()
    rows = [("Cycles, CPU", {"engine": "cycles", "device": "cpu"}, args.steps)]
    if gpu:
        rows.append((f"Cycles, GPU ({gpu})", {"engine": "cycles", "device": "gpu"}, args.steps))
    rows += [("Workbench", {"engine": "workbench"}, args.steps), ("EEVEE", {"engine": "eevee"}, args.slow_steps if not gpu else args.steps)]
    base = load_spec(resolve(args.spec))
    print(f"{args.spec}, one env, env steps/s (seconds to the first observation)")
    print(f"{'engine, device':<26} {'100x100':>18} {'512x512':>18}")
    for label, options, steps in rows:
        cells = []
        for size in (100, 512):
            rate, first = steps_per_s(with_resolution(base, size), steps, **options)
            cells.append(f"{rate:8.1f} ({first:5.1f} s)")
        print(f"{label:<26} {cells[0]:>18} {cells[1]:>18}", flush=True)


if __name__ == "__main__":
    main()
