"""Instructions an env's frame executes, counted by valgrind's callgrind: Cycles' path tracing per pixel, or a whole
step against Blender's render call of the same moved scene.

    python benchmarks/render_instructions.py [--renders 10] [IDS...]
    python benchmarks/render_instructions.py --step [--steps 100] [IDS...]
    python benchmarks/render_instructions.py --timed [--renders 200] [IDS...]

A count of instructions does not depend on the machine's load or clock, so it compares two versions of a scene's
shaders on a busy or drifting machine, where timings cannot (it is no time: a cache miss, a page the kernel clears or
a slow instruction costs more than one count). Each count runs in a process of its own under
``valgrind --tool=callgrind`` (a minute or two each; needs valgrind).

Default: the env resets and steps 5 times with zero actions (6 renders), then Blender's render call runs
``--renders`` times on that state; only instructions inside Cycles' path tracing
(``PathTraceWorkCPU::render_samples_full_pipeline``) are counted. Prints the count per render and per pixel.

``--step``: every instruction of three processes that differ only at their end: the env steps ``--steps`` seeded
random actions (resetting where an episode ends) or none, or steps them and then renders each step's state
again with Blender's render call alone (``bench``'s moved floor). Their differences give a step's instructions and
the render call's; what a step runs outside that call (physics, bindings, readback, Python; a reset's render counted
as a render) is printed against the call, as ``bench`` prints the time.

``--timed``: the default loop without valgrind, after 10 untimed calls: the median call (ms), for a before/after that
alternates processes (a ``git worktree`` of the commit before, the same venv).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

DEFAULT_IDS = ["VisualCartPole-v0", "DMC-cartpole-swingup-v0", "DMC-reacher-easy-v0", "DMC-cheetah-run-v0"]
#: renders before the counted ones: the reset's and five steps'
FIRST_RENDERS = 6
TRACING = "*render_samples_full_pipeline*"


def render(ident: str, renders: int, timed: bool = False) -> None:
    """A child: Blender's render call on one state. Prints the observation's pixels (and, timed, the median call)."""
    import time

    import numpy as np

    import visualenv

    env = visualenv.make(ident)
    obs, _ = env.reset(seed=0)
    for _ in range(FIRST_RENDERS - 1):
        obs, *_ = env.step(np.zeros_like(env.action_space.sample()))
    renderer = env.unwrapped.renderer
    calls = []
    for _ in range(renders + (10 if timed else 0)):
        start = time.perf_counter()
        renderer.raw_render()
        calls.append(time.perf_counter() - start)
    frame = next(iter(obs.values())) if isinstance(obs, dict) else obs
    print(f"pixels {frame.shape[0] * frame.shape[1]}")
    if timed:
        print(f"median_ms {1000 * np.median(calls[10:]):.3f}")
    env.close()


def step(ident: str, steps: int, floor: bool) -> None:
    """A child of ``--step``: `steps` seeded random steps, then (`floor`) each step's scene rendered again alone."""
    import bpy

    import visualenv

    env = visualenv.make(ident)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    base = env.unwrapped
    states, resets = [], 0
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        states.append(base.frames().copy())
        if terminated or truncated:
            env.reset()
            resets += 1
    if floor:
        for frames in states:
            base.renderer.write(frames)
            bpy.ops.render.render(scene=base.renderer.scene.name)
    print(f"resets {resets}")
    env.close()


def callgrind(args: list[str], toggle: str | None = None) -> tuple[int, str]:
    """The instructions callgrind counts in a child run with `args` (only inside `toggle` when given), and its output."""
    with tempfile.TemporaryDirectory() as folder:
        options = ["--collect-atstart=no", f"--toggle-collect={toggle}"] if toggle else []
        done = subprocess.run(
            ["valgrind", "--tool=callgrind", *options, f"--callgrind-out-file={Path(folder) / 'out'}",
             sys.executable, __file__, "--child", *args],
            capture_output=True, text=True, check=True, env={**os.environ, "PYTHONHASHSEED": "0"},
        )  # fmt: skip
    return int(re.search(r"Collected : (\d+)", done.stderr).group(1)), done.stdout  # type: ignore[union-attr]


def trace_row(ident: str, renders: int) -> str:
    collected, out = callgrind([ident, "--renders", str(renders)], TRACING)
    per_render, pixels = collected // (FIRST_RENDERS + renders), int(re.search(r"pixels (\d+)", out).group(1))  # type: ignore[union-attr]
    return f"| {ident} | {pixels} | {per_render / 1e6:.2f} | {per_render / pixels:,.0f} |"


def step_row(ident: str, steps: int) -> str:
    none, _ = callgrind([ident, "--step", "--steps", "0"])
    stepped, out = callgrind([ident, "--step", "--steps", str(steps)])
    floored, _ = callgrind([ident, "--step", "--steps", str(steps), "--floor"])
    resets = int(re.search(r"resets (\d+)", out).group(1))  # type: ignore[union-attr]
    call = (floored - stepped) / steps
    outside = (stepped - none - (steps + resets) * call) / steps
    return f"| {ident} | {steps} | {resets} | {(call + outside) / 1e6:.2f} | {call / 1e6:.2f} | {outside / call:.1%} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ids", nargs="*", default=DEFAULT_IDS)
    parser.add_argument("--renders", type=int, default=None, help="counted calls (default 10; timed, 200)")
    parser.add_argument("--step", action="store_true", help="a whole step against the render call")
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--timed", action="store_true", help="time the calls in this process instead")
    parser.add_argument("--floor", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child and args.step:
        step(args.ids[0], args.steps, args.floor)
    elif args.child or args.timed:
        for ident in args.ids:
            render(ident, args.renders or (200 if args.timed else 10), timed=args.timed)
    elif args.step:
        print("| id | steps | resets | a step (M) | the render call (M) | outside the call |")
        print("| --- | ---: | ---: | ---: | ---: | ---: |")
        for ident in args.ids:
            print(step_row(ident, args.steps), flush=True)
    else:
        print("| id | pixels | instructions per render (M) | per pixel |")
        print("| --- | ---: | ---: | ---: |")
        for ident in args.ids:
            print(trace_row(ident, args.renders or 10), flush=True)


if __name__ == "__main__":
    main()
