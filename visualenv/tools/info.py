"""`visualenv info`: versions, cores, and what Blender can render on this machine.

Blender is probed in a child process (:mod:`visualenv.render.blender.runtime.probe`) with a time
limit, so a GPU driver that crashes or hangs is reported, never fatal: ``info`` always exits 0.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
import sys
from typing import Any

from visualenv.env.cores import usable_cores
from visualenv.render.base import CYCLES_BACKENDS as BACKENDS
from visualenv.versions import __version__, mujoco_version

PROBE = [sys.executable, "-m", "visualenv.render.blender.runtime.probe"]
PROBE_TIMEOUT = 120.0
WARM_TIMEOUT = 1800.0  # compiling Cycles' kernels from PTX takes minutes (sm_90)


def gather(*, warm_gpu: bool = False, command: list[str] | None = None, timeout: float | None = None) -> dict[str, Any]:
    """Everything `info` prints, as a dict (``--json``)."""
    report: dict[str, Any] = {
        "python": platform.python_version(),
        "visualenv": __version__,
        "machine": platform.machine(),
        "mujoco": mujoco_version(),
        "cores": {"machine": os.cpu_count(), "usable": len(usable_cores())},
        "cuda_mps": cuda_mps(),
    }
    command = (command or PROBE) + (["--warm-gpu"] if warm_gpu else [])
    limit = timeout or (WARM_TIMEOUT if warm_gpu else PROBE_TIMEOUT)
    try:
        done = subprocess.run(
            command, stdout=subprocess.PIPE, stderr=None if warm_gpu else subprocess.DEVNULL, text=True, timeout=limit
        )
        lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
        if done.returncode != 0 or not lines:
            report["blender"] = {"error": f"the Blender probe ended with exit code {done.returncode} and no report"}
        else:
            report["blender"] = json.loads(lines[-1])
    except subprocess.TimeoutExpired:
        report["blender"] = {"error": f"the Blender probe did not answer in {limit:.0f} s"}
    except (OSError, ValueError) as exc:
        report["blender"] = {"error": f"the Blender probe failed: {exc}"}
    return report


def cuda_mps() -> dict[str, Any]:
    """Whether NVIDIA's Multi-Process Service is here and its daemon runs: worker processes rendering on one GPU
    (``make_vec(..., batched=True, workers=K)``) then share it without time-slicing. Its control daemon listens on a
    pipe named ``control`` in ``CUDA_MPS_PIPE_DIRECTORY`` (``/tmp/nvidia-mps`` by default)."""
    folder = os.environ.get("CUDA_MPS_PIPE_DIRECTORY", "/tmp/nvidia-mps")
    return {
        "control": shutil.which("nvidia-cuda-mps-control"),
        "pipe_directory": folder,
        "daemon": os.path.exists(os.path.join(folder, "control")),
    }


def _mps_line(mps: dict[str, Any]) -> str:
    if mps["daemon"]:
        return f"CUDA MPS: its daemon runs ({mps['pipe_directory']}): GPU workers share the GPU without time-slicing"
    if mps["control"]:
        return "CUDA MPS: installed, its daemon not running (start it with `nvidia-cuda-mps-control -d` before GPU workers)"
    return "CUDA MPS: not here (no nvidia-cuda-mps-control)"


def format_report(report: dict[str, Any]) -> str:
    cores = report["cores"]
    lines = [
        f"visualenv {report['visualenv']}, Python {report['python']} ({report['machine']})",
        f"cores: {cores['usable']} usable of {cores['machine']}",
        f"MuJoCo {report['mujoco']}"
        if report.get("mujoco")
        else "MuJoCo: not installed (physics specs need it: pip install 'visualenv[mujoco]')",
    ]
    if report.get("cuda_mps"):
        lines.append(_mps_line(report["cuda_mps"]))
    blender = report["blender"]
    if "error" in blender:
        return "\n".join(lines + [f"Blender: {blender['error']}"])
    lines.append(f"Blender (bpy) {blender.get('bpy', '?')}")
    cycles = blender.get("cycles", {})
    if "error" in cycles:
        lines.append(f"  Cycles devices: {cycles['error']}")
    else:
        for backend in BACKENDS:
            names = cycles.get(backend)
            lines.append(
                f"  Cycles {backend:<7} " + ("not in this build" if names is None else ", ".join(names) or "no device")
            )
    context = blender.get("gpu_context", {})
    if "error" in context:
        lines.append(f"  EEVEE/Workbench: no OpenGL context ({context['error']})")
    else:
        kind = "software rendering (no GPU): EEVEE takes seconds per frame" if context.get("software") else "a GPU"
        lines.append(f"  EEVEE/Workbench: {context.get('renderer')} ({context.get('backend')}), {kind}")
    batches = blender.get("batches", {})
    lines.append(
        "  batches (N envs per Cycles call, --batched): "
        + (
            "available: the custom OSL camera compiles and renders"
            if batches.get("available")
            else f"unavailable ({batches.get('error', 'not probed')})"
        )
    )
    for backend, facts in blender.get("kernels", {}).items():
        why = facts.get("compile_first")
        lines.append(
            f"  {backend} kernels: "
            + (
                f"compiled at the first GPU render ({why}); `visualenv info --warm-gpu` does it now"
                if why
                else "ready (shipped binary or cached)"
            )
        )
    for folder, filled in blender.get("kernel_caches", {}).items():
        lines.append(f"  kernel cache {folder}: {'filled' if filled else 'empty or absent'}")
    warm = blender.get("warm_gpu")
    if warm:
        lines.append(
            "  warm-gpu: "
            + (
                f"{warm['backend']} first frame in {warm['first_frame_s']} s"
                if warm.get("warmed")
                else warm.get("reason") or warm.get("error", "?")
            )
        )
    return "\n".join(lines)
