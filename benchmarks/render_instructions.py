"""Instructions Cycles' path tracing executes per pixel of an env's frame, counted by valgrind's callgrind.

    python benchmarks/render_instructions.py [--renders 10] [IDS...]
    python benchmarks/render_instructions.py --timed [--renders 200] [IDS...]

A count of instructions does not depend on the machine's load or clock, so it compares two versions of a scene's
shaders on a busy or drifting machine, where timings cannot (it is no time: a cache miss or a slow instruction costs
more than one count). For each id, in a process of its own under ``valgrind --tool=callgrind``: the env resets and
steps 5 times with zero actions (6 renders), then Blender's render call runs ``--renders`` times on that state; only
instructions inside Cycles' path tracing (``PathTraceWorkCPU::render_samples_full_pipeline``) are counted. Prints the
count per render and per pixel of the observation. Needs valgrind; each id takes a minute or two.

``--timed``: the same loop without valgrind, after 10 untimed calls: the median call (ms), for a before/after that
alternates processes (a ``git worktree`` of the commit before, the same venv).
"""

from __future__ import annotations

import argparse
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
    """The child: what valgrind runs. Prints the observation's pixels (and, timed, the median call in ms)."""
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


def count(ident: str, renders: int) -> tuple[int, int]:
    """Instructions per render in path tracing, and the observation's pixels."""
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "callgrind.out"
        done = subprocess.run(
            ["valgrind", "--tool=callgrind", "--collect-atstart=no", f"--toggle-collect={TRACING}",
             f"--callgrind-out-file={out}", sys.executable, __file__, "--child", ident, "--renders", str(renders)],
            capture_output=True, text=True, check=True,
        )  # fmt: skip
    collected = int(re.search(r"Collected : (\d+)", done.stderr).group(1))  # type: ignore[union-attr]
    pixels = int(re.search(r"pixels (\d+)", done.stdout).group(1))  # type: ignore[union-attr]
    return collected // (FIRST_RENDERS + renders), pixels


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ids", nargs="*", default=DEFAULT_IDS)
    parser.add_argument("--renders", type=int, default=None, help="counted calls (default 10; timed, 200)")
    parser.add_argument("--timed", action="store_true", help="time the calls in this process instead")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child or args.timed:
        for ident in args.ids:
            render(ident, args.renders or (200 if args.timed else 10), timed=args.timed)
        return
    args.renders = args.renders or 10
    print("| id | pixels | instructions per render (M) | per pixel |")
    print("| --- | ---: | ---: | ---: |")
    for ident in args.ids:
        per_render, pixels = count(ident, args.renders)
        print(f"| {ident} | {pixels} | {per_render / 1e6:.2f} | {per_render / pixels:,.0f} |", flush=True)


if __name__ == "__main__":
    main()
