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

``--functions N``: the default count, then the N functions of Cycles' tracing that run the most instructions,
each with what it calls (callgrind_annotate, inclusive), as shares of the tracing: where a frame's tracing goes
(the surface shaders, the light's sample and its shader, shadow rays, random numbers), in counts and not time.

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


def callgrind(args: list[str], toggle: str | None = None, functions: int = 0) -> tuple[int, str, str]:
    """The instructions callgrind counts in a child run with `args` (only inside `toggle` when given), its output, and
    with `functions` the rows of :func:`function_rows`."""
    with tempfile.TemporaryDirectory() as folder:
        options = ["--collect-atstart=no", f"--toggle-collect={toggle}"] if toggle else []
        out = Path(folder) / "out"
        done = subprocess.run(
            ["valgrind", "--tool=callgrind", *options, f"--callgrind-out-file={out}",
             sys.executable, __file__, "--child", *args],
            capture_output=True, text=True, check=True, env={**os.environ, "PYTHONHASHSEED": "0"},
        )  # fmt: skip
        table = function_rows(out, functions) if functions else ""
    return int(re.search(r"Collected : (\d+)", done.stderr).group(1)), done.stdout, table  # type: ignore[union-attr]


#: a row of ``callgrind_annotate --inclusive=yes``: the count, its share, then ``file:function [object]``
ANNOTATED = re.compile(r"^\s*([\d,]+) \(\s*([\d.]+)%\)\s+\S*?:(.+?)(?: \[[^\]]*\])?\s*$")


def function_rows(out: Path, most: int) -> str:
    """The `most` functions below the megakernel that run the most instructions (with what they call), as table rows."""
    annotated = subprocess.run(
        ["callgrind_annotate", "--inclusive=yes", str(out)], capture_output=True, text=True, check=True
    ).stdout
    rows, below = [], False
    for line in annotated.splitlines():
        found = ANNOTATED.match(line)
        if found is None:
            continue
        count, share, name = found.groups()
        below = below or "integrator_megakernel" in name
        if below and "integrator_megakernel" not in name and not name.startswith("0x"):
            rows.append(f"| | {_short(name)} | {int(count.replace(',', '')) / 1e6:.1f} | {share} % |")
    return "\n".join(rows[:most])


def _short(name: str) -> str:
    """A C++ name without its return type and parameters, with only its first template argument, which tells apart
    the instances of one template (``ccl::svm_eval_nodes<16779195u>``: the surface shaders' node features)."""
    name = name.replace("(anonymous namespace)::", "")
    first = re.match(r"[^<(]*<([^,<>]*)", name)
    while "<" in name:
        name = re.sub(r"<[^<>]*>", "", name)
    name = re.sub(r"\(.*$", "", name)
    name = name.split()[-1] if name.split() else name
    return f"{name}<{first.group(1)}>" if first else name


def trace_row(ident: str, renders: int, functions: int = 0) -> str:
    collected, out, table = callgrind([ident, "--renders", str(renders)], TRACING, functions)
    per_render, pixels = collected // (FIRST_RENDERS + renders), int(re.search(r"pixels (\d+)", out).group(1))  # type: ignore[union-attr]
    row = f"| {ident} | {pixels} | {per_render / 1e6:.2f} | {per_render / pixels:,.0f} |"
    return row + ("\n" + table if table else "")


def step_row(ident: str, steps: int) -> str:
    none, _, _ = callgrind([ident, "--step", "--steps", "0"])
    stepped, out, _ = callgrind([ident, "--step", "--steps", str(steps)])
    floored, _, _ = callgrind([ident, "--step", "--steps", str(steps), "--floor"])
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
    parser.add_argument("--functions", type=int, default=0, metavar="N", help="and the N costliest functions")
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
    elif args.functions:
        print(
            "| id, then a function and what it calls | pixels | instructions (M: per render, then all renders) | per pixel, then share |"
        )
        print("| --- | --- | ---: | ---: |")
        for ident in args.ids:
            print(trace_row(ident, args.renders or 10, args.functions), flush=True)
    else:
        print("| id | pixels | instructions per render (M) | per pixel |")
        print("| --- | ---: | ---: | ---: |")
        for ident in args.ids:
            print(trace_row(ident, args.renders or 10), flush=True)


if __name__ == "__main__":
    main()
