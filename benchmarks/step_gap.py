"""Where a step's time goes beyond Blender's own render, by thread: one env's step against the same scene's bare
render call, each thread's CPU time per step beside the wall time.

    python benchmarks/step_gap.py [ID] [--rounds 5] [--steps 300]

In one process, over the states of seeded random steps, blocks of each kind in turn, every round:

* step: ``env.step`` (physics, episode rules, bindings written, the render call, the pass read back and converted);
* floor: the same states written (``renderer.write``: bound objects, MuJoCo's bodies and cameras) and a bare
  ``bpy.ops.render.render``, nothing read;
* captured: the same with the renderer's capture armed (the Combined pass copied out of Cycles);
* conversion: the armed render, then only the pass's conversion to the observation's bytes timed.

Each thread's CPU time comes from ``/proc/self/task/<tid>/stat`` before and after a block (Linux only): the main
thread's is the Python side and Blender's operator, depsgraph and sync; the others are Cycles' and TBB's workers,
which spin between renders as well as trace. Figures are medians over the rounds, in ms per step.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

TICK_MS = 1000 / os.sysconf("SC_CLK_TCK")


def thread_cpu_ms() -> dict[int, float]:
    """Each thread's user + system CPU time so far, in ms."""
    times = {}
    for task in Path("/proc/self/task").iterdir():
        fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        times[int(task.name)] = (int(fields[11]) + int(fields[12])) * TICK_MS
    return times


def block(run, steps: int) -> tuple[float, float, float]:
    """Wall ms per step, the main thread's CPU ms per step and the other threads' together."""
    main = os.getpid()
    before, start = thread_cpu_ms(), time.perf_counter()
    run()
    wall, after = time.perf_counter() - start, thread_cpu_ms()
    spent = {tid: after[tid] - before.get(tid, 0.0) for tid in after}
    own = spent.pop(main, 0.0)
    return 1000 * wall / steps, own / steps, sum(spent.values()) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("id", nargs="?", default="VisualCartPole-v0")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=300)
    args = parser.parse_args()

    import bpy

    import visualenv

    env = visualenv.make(args.id)
    base = env.unwrapped
    renderer = base.renderer
    env.reset(seed=0)  # renders: the in-memory readback is armed for the observation camera from here on
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(args.steps)]
    states = []
    for action in actions:  # warm-up, and the states the floor blocks write
        if any(env.step(action)[2:4]):
            env.reset()
        states.append(base.frames().copy())
    scene = renderer.scene.name

    def steps() -> None:
        for action in actions:
            if any(env.step(action)[2:4]):
                env.reset()

    def floor() -> None:
        for frames in states:
            renderer.write(frames)
            bpy.ops.render.render(scene=scene)

    def captured() -> None:
        for frames in states:
            renderer.write(frames)
            renderer.raw_render()  # Blender's call, the pass copied out

    conversions: list[float] = []

    def converted() -> None:
        for frames in states:
            renderer.write(frames)
            renderer.raw_render()
            start = time.perf_counter()
            renderer.read_again()
            conversions.append(time.perf_counter() - start)

    kinds = {"step": steps, "floor": floor, "captured": captured, "conversion": converted}
    figures: dict[str, list[tuple[float, float, float]]] = {kind: [] for kind in kinds}
    for _ in range(args.rounds):
        for kind, run in kinds.items():
            figures[kind].append(block(run, args.steps))
    env.close()

    print(f"{args.id}: {args.rounds} rounds of {args.steps} steps per kind, ms per step (medians over the rounds)")
    print(f"{'kind':12s} {'wall':>7s} {'main CPU':>9s} {'others CPU':>11s}")
    for kind, rows in figures.items():
        wall, own, others = np.median(np.array(rows), axis=0)
        print(f"{kind:12s} {wall:7.3f} {own:9.3f} {others:11.3f}")
    print(f"the conversion alone (median of {len(conversions)}): {1000 * np.median(conversions):.3f} ms")


if __name__ == "__main__":
    main()
