"""What Blender can render on here: Cycles devices per backend, the GPU context of EEVEE/Workbench, kernel caches.

:mod:`visualenv.render.blender.runtime.probe` runs these in a child process for ``visualenv info``
(a driver that crashes takes only the probe with it).

Also the one-line notice before a process's first Cycles GPU render when Blender must first
compile its kernels for this GPU: bpy 5.0.1 ships CUDA binaries for some architectures only
(``kernel_sm_XX.cubin``), and OptiX runs those CUDA kernels beside its own; the driver then caches
the compiled PTX, so it happens once per machine. On an H100 or H200 (sm_90) that first frame takes minutes; with an
sm_90 binary compiled ahead (docs/performance.md, *On a GPU*), seconds (OptiX's own modules).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from visualenv.compat.blender import cached_kernels, cycles_addon, use_cached_kernels
from visualenv.render.base import CYCLES_BACKENDS as BACKENDS

NVIDIA = ("CUDA", "OPTIX")
GPU_BACKENDS = ("OPTIX", "CUDA", "HIP", "METAL", "ONEAPI")  # the order detect_gpu prefers them in


@dataclass(frozen=True)
class KernelFacts:
    """What decides whether the first GPU render compiles kernels (gathered by :func:`kernel_facts`)."""

    backend: str
    # CUDA architectures with a binary in bpy or compiled ahead (compile-kernels), e.g. 'sm_75'
    shipped_archs: tuple[str, ...]
    gpu_archs: tuple[str, ...]  # this machine's NVIDIA GPUs (e.g. 'sm_90'); empty if unknown
    caches: tuple[tuple[str, bool], ...]  # (folder, whether it holds anything)


def kernels_to_compile(facts: KernelFacts) -> str | None:
    """Why the first render must compile kernels, or None when shipped binaries or a filled cache serve it."""
    if facts.backend not in NVIDIA or any(filled for _, filled in facts.caches):
        return None
    missing = [arch for arch in facts.gpu_archs if arch not in facts.shipped_archs]
    if not missing:  # OptiX still builds its own modules from PTX, but in seconds
        return None
    if facts.backend == "OPTIX":
        return f"OptiX runs Cycles' CUDA kernels too, and bpy has no CUDA binary for {', '.join(missing)}: the driver compiles its PTX"
    return f"bpy ships no CUDA binary for {', '.join(missing)}: the driver compiles its PTX"


def compile_notice(facts: KernelFacts) -> str | None:
    """The line printed before the first GPU render of a process that must compile kernels first."""
    why = kernels_to_compile(facts)
    if why is None:
        return None
    where = " and ".join(folder for folder, _ in facts.caches)
    return (
        f"visualenv: Cycles compiles its {facts.backend} kernels for this GPU before the first frame ({why}): "
        f"minutes, once per machine; the driver caches them in {where}. `visualenv info --warm-gpu` does it ahead of training."
    )


def cycles_lib() -> Path | None:
    """bpy's folder of Cycles kernel binaries (found without importing bpy)."""
    addon = cycles_addon()
    return addon / "lib" if addon is not None else None


def shipped_cuda_archs(lib: Path | None = None) -> tuple[str, ...]:
    """The CUDA architectures bpy ships a binary for (``kernel_sm_XY.cubin.zst``)."""
    lib = lib or cycles_lib()
    if lib is None:
        return ()
    return tuple(sorted(m.group(1) for p in lib.iterdir() if (m := re.match(r"kernel_(sm_\d+)\.cubin", p.name))))


def nvidia_archs() -> tuple[str, ...]:
    """Compute capabilities of this machine's NVIDIA GPUs as 'sm_XY' (nvidia-smi; empty without it)."""
    if shutil.which("nvidia-smi") is None:
        return ()
    try:
        out = subprocess.run(
            ["nvidia-smi", "--query-gpu=compute_cap", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=20,
            check=True,
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return ()
    return tuple(sorted({"sm_" + line.strip().replace(".", "") for line in out.splitlines() if line.strip()}))


def kernel_caches() -> tuple[tuple[str, bool], ...]:
    """The driver's kernel caches (CUDA's ComputeCache, OptiX's cache) and whether each holds anything."""
    user = os.environ.get("USER") or ("root" if os.geteuid() == 0 else str(os.geteuid()))
    folders = [
        os.environ.get("CUDA_CACHE_PATH") or str(Path.home() / ".nv" / "ComputeCache"),
        f"/var/tmp/OptixCache_{user}",
    ]
    return tuple((folder, Path(folder).is_dir() and any(Path(folder).rglob("*"))) for folder in folders)


def kernel_facts(backend: str) -> KernelFacts:
    """What decides whether the first render on `backend` compiles kernels: binaries shipped or compiled ahead, GPUs, caches."""
    archs = tuple(sorted({*shipped_cuda_archs(), *cached_kernels()}))
    return KernelFacts(backend, archs, nvidia_archs() if backend in NVIDIA else (), kernel_caches())


_gpu_cache: str | None | bool = False  # False: not probed yet


def detect_gpu() -> str | None:
    """The first Cycles GPU backend with a usable device (all its devices enabled), or None."""
    global _gpu_cache
    if _gpu_cache is not False:
        return _gpu_cache  # type: ignore[return-value]
    found = None
    try:
        import bpy

        prefs = bpy.context.preferences.addons["cycles"].preferences
        for backend in GPU_BACKENDS:
            try:
                prefs.compute_device_type = backend
            except TypeError:  # backend not compiled into this build
                continue
            prefs.refresh_devices()
            devices = [d for d in prefs.devices if d.type == backend]
            if devices:
                for d in prefs.devices:
                    d.use = d.type == backend
                found = backend
                break
        if found is None:
            prefs.compute_device_type = "NONE"
    except Exception:  # noqa: BLE001 - no Cycles preferences: treat as no GPU
        found = None
    _gpu_cache = found
    return found


def cycles_devices() -> dict[str, list[str]]:
    """Device names per Cycles backend that this build has (CPU included); a backend without devices maps to []."""
    import bpy

    prefs = bpy.context.preferences.addons["cycles"].preferences
    found: dict[str, list[str]] = {}
    for backend in BACKENDS[1:]:
        try:
            prefs.compute_device_type = backend
        except TypeError:  # not compiled into this build
            continue
        prefs.refresh_devices()
        found[backend] = [d.name for d in prefs.devices if d.type == backend]
        found.setdefault("CPU", [d.name for d in prefs.devices if d.type == "CPU"])
    prefs.compute_device_type = "NONE"
    return {b: found[b] for b in BACKENDS if b in found}


def _tiny_scene(name: str, engine: str) -> Any:
    """A 16x16 scene with a camera and nothing else: what a probe renders."""
    import bpy

    scene = bpy.data.scenes.new(name)
    scene.render.engine = engine
    scene.render.resolution_x = scene.render.resolution_y = 16
    camera = bpy.data.objects.new(name + "-camera", bpy.data.cameras.new(name + "-camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    return scene


def gpu_context() -> dict[str, Any]:
    """The OpenGL/EGL context EEVEE and Workbench get: a 16x16 Workbench render, then what the gpu module reports."""
    import bpy
    import gpu

    bpy.ops.render.render(scene=_tiny_scene("visualenv-probe", "BLENDER_WORKBENCH").name)
    renderer = gpu.platform.renderer_get()
    device = gpu.platform.device_type_get()
    return {
        "renderer": renderer,
        "vendor": gpu.platform.vendor_get(),
        "backend": gpu.platform.backend_type_get(),
        "device_type": device,
        "software": device == "SOFTWARE" or "llvmpipe" in renderer.lower(),
    }


def warm_gpu() -> dict[str, Any]:
    """Render one small Cycles frame on the GPU, so the driver compiles and caches the kernels now."""
    from visualenv.render.blender.runtime.log import blender_output

    backend = detect_gpu()
    if backend is None:
        return {"warmed": False, "reason": "no Cycles GPU device"}
    use_cached_kernels()
    notice = compile_notice(kernel_facts(backend))
    if notice:
        print(notice, file=sys.stderr, flush=True)
    with blender_output():
        return _render_on_gpu(backend)


def _render_on_gpu(backend: str) -> dict[str, Any]:
    import time

    import bpy

    scene = _tiny_scene("visualenv-warm", "CYCLES")
    scene.cycles.device = "GPU"
    scene.cycles.samples = 1
    started = time.perf_counter()
    bpy.ops.render.render(scene=scene.name)
    return {"warmed": True, "backend": backend, "first_frame_s": round(time.perf_counter() - started, 2)}
