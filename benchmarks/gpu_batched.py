"""`bench --batched` for a lease on a GPU machine: every (spec, N, K) in its own process with a time limit, each row
printed and appended to a JSON-lines file as soon as it is measured, so a lease that ends early keeps every finished row.

The first job renders a small batch once, so that Cycles compiles its GPU kernels (and the tiles camera's OSL
shader) before anything is timed; its build time is that compile. Rows then come in the order of the plan, most
wanted first; no job starts in the deadline's last 20 s, and a job still running at the deadline is stopped. K = 1 is one batch in one process (the figures of
``measure_batch``, stage by stage); K > 1 splits N among K worker processes (``MultiBatchVectorEnv``).

    python benchmarks/gpu_batched.py OUT.jsonl [--device gpu] [--deadline-s 420] [--plan cartpole:64,256:1 goalie:1024:1:cpu ...]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

SPECS = {"cartpole": "specs/visual_cartpole.yaml", "goalie": "specs/goalie.yaml"}
DEFAULT_PLAN = ["cartpole:64,256,1024,4096:1", "goalie:64,256,1024,4096:1", "cartpole:1024,4096:4", "goalie:1024,4096:4",
                "cartpole:4096:8", "goalie:4096:8", "cartpole:1024:2", "cartpole:1024:1:cpu", "cartpole:1024:8:cpu"]
CHILD = """
import json, sys
from visualenv.compat.glibc import apply_policy
apply_policy()  # what `visualenv bench --batched` does in its measuring process (freed memory kept for the next call)
from visualenv.tools.bench_batch import measure_batch, measure_workers
spec, n, k, steps, device = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), sys.argv[5] or None
if k == 1:
    row = measure_batch(spec, n, steps, device=device)
    from visualenv.render.blender.runtime.devices import detect_gpu
    row["backend"] = detect_gpu() if device != "cpu" else "CPU"
else:
    row = measure_workers(spec, n, k, steps, device=device)
print("ROW " + json.dumps(row), flush=True)
"""


def steps_for(n: int) -> int:
    """Measured steps of all N envs: enough for a median, few where a step is long."""
    return max(8, min(60, 16384 // n))


def run_job(spec: str, n: int, k: int, steps: int, device: str, limit: float) -> dict:
    started = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-c", CHILD, SPECS.get(spec, spec), str(n), str(k), str(steps), device],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        stdout, stderr = child.communicate(timeout=limit)
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)  # its worker processes too
        child.communicate()
        return {"envs": n, "workers": k, "error": f"over its {limit:.0f} s limit"}
    rows = [line[4:] for line in stdout.splitlines() if line.startswith("ROW ")]
    if not rows:
        return {"envs": n, "workers": k, "error": f"exit {child.returncode}: {stderr.strip()[-600:]}"}
    row = json.loads(rows[-1])
    row.update(workers=k, wall_s=round(time.perf_counter() - started, 1))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--device", default="gpu", choices=["gpu", "cpu"])
    parser.add_argument("--deadline-s", type=float, default=420.0, help="stop every job this many seconds after the start")
    parser.add_argument("--plan", nargs="*", default=DEFAULT_PLAN, help="spec:N,N,...:K[:device] items, in order")
    args = parser.parse_args()
    start = time.perf_counter()
    jobs = [("cartpole", 16, 1, 3, args.device, "warm")]
    for item in args.plan:
        spec, sizes, k, *device = item.split(":")
        jobs += [(spec, int(n), int(k), steps_for(int(n)), device[0] if device else args.device, "") for n in sizes.split(",")]
    with args.out.open("a") as out:
        for spec, n, k, steps, device, tag in jobs:
            left = args.deadline_s - (time.perf_counter() - start)
            if left < 20:
                print(f"deadline: {spec} N={n} K={k} and the rest not started", flush=True)
                break
            row = run_job(spec, n, k, steps, device, left)
            row.update(spec=spec, device=device, tag=tag, steps=steps)
            out.write(json.dumps(row) + "\n")
            out.flush()
            figures = (f"{row['steps_per_s']:.0f} env-steps/s, step {row['step_ms']:.1f} ms, build {row['build_s']:.1f} s"
                       if "error" not in row else row["error"])
            extra = (f", render {row['render_ms']:.1f} update {row['scene_update_ms']:.1f} readback {row['readback_ms']:.1f} "
                     f"write {row['write_ms']:.2f} calls {row['calls_per_step']:.2f} alone {row['alone_ms']:.1f} {row.get('backend')}"
                     if "render_ms" in row else "")
            print(f"[{time.perf_counter() - start:6.0f} s] {tag or spec} N={n} K={k} {device}: {figures}{extra}", flush=True)


if __name__ == "__main__":
    main()
