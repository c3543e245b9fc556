"""Cycles' CUDA kernels compiled ahead for a GPU that bpy ships no binary for (``visualenv compile-kernels``).

bpy 5.0.1 ships CUDA binaries (``kernel_sm_XX.cubin.zst``) for some architectures and PTX
(``kernel_compute_XY.ptx.zst``) for the rest. On an H100 or H200 (sm_90) the driver compiles that
PTX at the first GPU frame, OptiX included (it runs Cycles' CUDA kernels beside its own): minutes,
cached per machine in ``~/.nv/ComputeCache``. A machine that starts bare (a cloud
instance, a container) pays it at every start. Compiled once with the CUDA toolkit's ``ptxas``,
the first frame takes seconds (docs/performance.md, *On a GPU*; results/benchmarks/batched-gpu-h200.md).
The binary goes to visualenv's kernel cache (``$XDG_CACHE_HOME/visualenv/cycles``, keyed by bpy's version and the
PTX's hash), never into bpy's installed package; a process that renders on the GPU points Cycles at
it (:func:`visualenv.compat.blender.use_cached_kernels`). Compile in the image the machines start from
(or with ``XDG_CACHE_HOME`` on a shared disk), with a ``ptxas`` no newer than their driver supports.
Needs no GPU, only bpy's files.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from visualenv.compat import blender as compat
from visualenv.errors import ConfigError


def find_ptxas(given: str | None = None) -> str:
    """The CUDA toolkit's ptxas: `given`, else on PATH, else under CUDA_HOME or /usr/local/cuda."""
    candidates = (
        [given]
        if given
        else [
            shutil.which("ptxas"),
            *(str(Path(root) / "bin" / "ptxas") for root in (os.environ.get("CUDA_HOME"), "/usr/local/cuda") if root),
        ]
    )
    for candidate in candidates:
        if candidate and Path(candidate).is_file() and os.access(candidate, os.X_OK):
            return candidate
    where = (
        f"{given} is not an executable file" if given else "not on PATH, nor in $CUDA_HOME/bin or /usr/local/cuda/bin"
    )
    raise ConfigError(
        f"compiling Cycles' kernels needs the CUDA toolkit's ptxas ({where}): install the toolkit "
        f"(its version no newer than the GPU driver supports) or name it with --ptxas"
    )


def source_ptx(arch: str, lib: Path) -> Path:
    """The PTX that compiles for `arch`: bpy's highest ``kernel_compute_XY`` not above it (the one Cycles would load)."""
    ptx = compat.source_ptx(arch, lib)
    if ptx is None:
        found = sorted(
            int(m.group(1))
            for p in lib.glob("kernel_compute_*.ptx.zst")
            if (m := re.fullmatch(r"kernel_compute_(\d+)\.ptx\.zst", p.name))
        )
        raise ConfigError(
            f"bpy ships no PTX that compiles for {arch} in {lib} (has: {', '.join(f'compute_{n}' for n in found) or 'none'})"
        )
    return ptx


def compile_cuda_kernels(arch: str, *, lib: Path | None = None, ptxas: str | None = None) -> Path:
    """Compile bpy's Cycles PTX for `arch` ('sm_90') into the kernel cache, as ``kernel_<arch>.cubin.zst``
    (:func:`visualenv.compat.blender.cached_kernel`); `lib`: the folder of the PTX (default: bpy's).

    Takes minutes of one core: ptxas compiles Cycles' whole kernel. The file is
    written whole or not at all. Returns its path.
    """
    import zstandard  # a dependency of bpy: Cycles reads its kernels zstd-compressed

    if not re.fullmatch(r"sm_\d{2,3}", arch):
        raise ConfigError(f"expected a CUDA architecture such as sm_90, got {arch!r}")
    addon = compat.cycles_addon()
    folder = lib or (addon / "lib" if addon is not None else None)
    version = compat.bpy_version()
    if folder is None or version is None:
        raise ConfigError("bpy is not installed here: there are no Cycles kernels to compile")
    ptx = source_ptx(arch, folder)
    tool = find_ptxas(ptxas)
    target = compat.cached_kernel(arch, ptx, version)
    with tempfile.TemporaryDirectory() as tmp:
        plain, cubin = Path(tmp) / "kernel.ptx", Path(tmp) / "kernel.cubin"
        plain.write_bytes(zstandard.ZstdDecompressor().decompressobj().decompress(ptx.read_bytes()))
        done = subprocess.run(
            [tool, f"-arch={arch}", "-O3", str(plain), "-o", str(cubin)], capture_output=True, text=True
        )
        if done.returncode != 0:
            raise ConfigError(
                f"ptxas could not compile {ptx.name} for {arch}: {(done.stderr or done.stdout).strip()[-800:]}"
            )
        partial = target.parent / f".{target.name}.partial"
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            partial.write_bytes(zstandard.ZstdCompressor(level=19).compress(cubin.read_bytes()))
            partial.replace(target)
        except OSError as exc:
            partial.unlink(missing_ok=True)
            raise ConfigError(
                f"cannot write {target}: {exc.strerror or exc} (set XDG_CACHE_HOME to a writable folder)"
            ) from None
    return target
