"""``python -m visualenv.render.blender.runtime.probe``: what ``visualenv info`` reports about Blender, as one JSON object.

Run in a child process, so that a GPU driver that crashes or hangs takes only the probe with it.
Its own module because it gathers from both :mod:`.devices` (Cycles devices, EEVEE's context,
kernels) and :mod:`.batched` (whether a batch's custom camera compiles), which :mod:`.devices`,
imported by the renderer's settings, cannot import.
"""

from __future__ import annotations

import json
import sys
from typing import Any

from visualenv.render.blender.batch.tiles_camera import tiles_camera_check
from visualenv.render.blender.runtime.devices import (
    NVIDIA,
    cycles_devices,
    gpu_context,
    kernel_caches,
    kernel_facts,
    kernels_to_compile,
    warm_gpu,
)


def probe(warm: bool = False) -> dict[str, Any]:
    """Everything `visualenv info` reports about Blender; each part that fails says why instead of failing the rest."""
    from visualenv.render.blender.runtime.log import blender_output

    import bpy

    report: dict[str, Any] = {"bpy": bpy.app.version_string}
    for key, part in (("cycles", cycles_devices), ("gpu_context", gpu_context), ("batches", tiles_camera_check)):
        try:
            with blender_output():
                report[key] = part()
        except Exception as exc:  # noqa: BLE001 - a probe reports what went wrong; it never stops the others
            report[key] = {"error": f"{type(exc).__name__}: {exc}"}
    if warm:
        try:
            report["warm_gpu"] = warm_gpu()  # prints its notice to stderr itself, before the long first frame
        except Exception as exc:  # noqa: BLE001
            report["warm_gpu"] = {"error": f"{type(exc).__name__}: {exc}"}
    gpus = (
        [b for b, names in report.get("cycles", {}).items() if b != "CPU" and names]
        if isinstance(report.get("cycles"), dict)
        else []
    )
    report["kernels"] = {b: {"compile_first": kernels_to_compile(kernel_facts(b))} for b in gpus if b in NVIDIA}
    report["kernel_caches"] = {folder: filled for folder, filled in kernel_caches()}
    return report


if __name__ == "__main__":
    print(json.dumps(probe(warm="--warm-gpu" in sys.argv[1:])), flush=True)
