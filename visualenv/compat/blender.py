"""What visualenv relies on in Blender (bpy) and Cycles beyond their documented API, in one place.

Each part says what it relies on and why no documented mechanism does the job. All were checked against the
bpy versions in :data:`CHECKED_BPY`; on another bpy each warns once (:func:`check_bpy`) and the CUDA kernel
cache is left unused. ``tests/compat/test_blender.py`` checks every part against the installed bpy and fails,
naming the part, when bpy moves.

- bpy's bundled Python packages (``oslquery``, which compiling an OSL camera shader needs) on ``sys.path``, and
  the script folders a spawned process inherits from one that imported bpy dropped from it;
- Cycles' render method wrapped, so that its result is copied while the engine still holds it (:mod:`capture`);
- the arithmetic of Blender's object matrices, to the bit (its SSE order of sums), for numpy-posed instances;
- Blender's render results, one per scene name, never freed with the scene: scene names reused, a tiny last frame;
- a BMesh's faces put in one order (bmesh's UV sphere lists them in a per-process order, which moved the last bits of
  every sphere's shading from one process to the next);
- Cycles' CUDA kernels compiled ahead into a cache outside site-packages, and Cycles pointed at it.

Importing this module does not import bpy (its functions do, where they need it): the kernel cache serves
``visualenv compile-kernels`` without loading Blender.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import os
import re
import shutil
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np

#: the bpy versions every part of this module was checked against
CHECKED_BPY = ("5.0.1",)

_warned: set[str] = set()


def bpy_version() -> str | None:
    """The installed bpy's version ("5.0.1"), read from its package metadata (bpy is not imported); None without bpy."""
    try:
        return importlib.metadata.version("bpy")
    except importlib.metadata.PackageNotFoundError:
        return None


def check_bpy(part: str) -> bool:
    """Whether the installed bpy is one `part` was checked against; if not, a warning once per part and process."""
    version = bpy_version()
    if version in CHECKED_BPY:
        return True
    if part not in _warned:
        _warned.add(part)
        warnings.warn(
            f"visualenv's {part} relies on Blender internals checked against bpy {', '.join(CHECKED_BPY)}, "
            f"not {version}: run tests/compat/test_blender.py",
            RuntimeWarning,
            stacklevel=3,
        )
    return False


# -- bpy's Python packages ------------------------------------------------------------------------------------------


def drop_inherited_script_paths() -> None:
    """Drop Blender's script folders from ``sys.path`` in a process that has not imported bpy yet.

    A process spawned by one that imported bpy inherits those folders; their ``bpy`` package would shadow the real
    module ("No module named '_bpy'"). bpy adds them again itself on import.
    """
    if "bpy" in sys.modules:
        return
    marker = os.sep + "bpy" + os.sep
    sys.path[:] = [p for p in sys.path if not (marker in p and os.sep + "scripts" in p)]


def bundled_packages_on_path() -> None:
    """Append bpy's own site-packages to ``sys.path`` (once): Cycles' OSL compiler imports ``oslquery`` (and it
    ``OpenImageIO``) from there. Blender's own executable has that folder on its path; bpy as a module does not.
    Appended last, so that packages the user installed win."""
    import bpy

    check_bpy("path to bpy's bundled Python packages")
    local = bpy.utils.resource_path("LOCAL")
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    for lib in ("lib", "lib64"):
        path = f"{local}/python/{lib}/{version}/site-packages"
        if path not in sys.path:
            sys.path.append(path)


def compile_camera_shader(camera: Any, scene: Any) -> None:
    """Compile a custom camera's OSL shader and give its data a property per shader parameter: Blender's "Update
    Custom Camera" operator (``object.camera_custom_update``) on `camera` in `scene` (which renders with Cycles).
    Raises RuntimeError when Cycles cannot (its messages went to the console)."""
    import bpy

    bundled_packages_on_path()
    with bpy.context.temp_override(scene=scene, object=camera, active_object=camera):
        if not bpy.ops.object.camera_custom_update.poll():
            raise RuntimeError(
                "Blender cannot update this custom camera (not a custom camera, or the scene's engine is not Cycles)"
            )
        bpy.ops.object.camera_custom_update()


# -- Cycles' render method ------------------------------------------------------------------------------------------


def _cycles_method(name: str) -> Any:
    """Cycles' engine method `name` ("update" or "render"), wrapped once per process so that it calls the functions in
    its ``_visualenv_before`` and ``_visualenv_after`` lists (each ``f(engine)``) around the original; None without
    the Cycles add-on."""
    try:
        import cycles  # Blender's bundled add-on, importable once bpy is

        engine_class = cycles.CyclesRender
    except (ImportError, AttributeError):
        return None
    check_bpy(f"wrapper of Cycles' {name} method")
    method = getattr(engine_class, name)
    if getattr(method, "_visualenv_after", None) is not None:
        return method
    original = method

    def around(engine: Any, *args: Any) -> None:
        for call in list(wrapper._visualenv_before):  # type: ignore[attr-defined]
            call(engine)
        original(engine, *args)
        for call in list(wrapper._visualenv_after):  # type: ignore[attr-defined]
            call(engine)

    # explicit arguments: Blender passes as many as the method names
    if name == "render":

        def wrapper(self: Any, depsgraph: Any) -> None:
            around(self, depsgraph)
    else:

        def wrapper(self: Any, data: Any, depsgraph: Any) -> None:  # type: ignore[misc]
            around(self, data, depsgraph)

    wrapper._visualenv_before = []  # type: ignore[attr-defined]
    wrapper._visualenv_after = []  # type: ignore[attr-defined]
    setattr(engine_class, name, wrapper)
    return wrapper


def wrap_cycles_render(after: Callable[[Any], None]) -> bool:
    """Have Cycles' engine call ``after(engine)`` at the end of each render, while it still holds its result
    (``engine.get_result()``); once per process. False when this bpy has no Cycles add-on.

    Why: in background mode Blender gives Python no access to a finished render (the 'Render Result' image has no
    pixels); only the engine reads its result, inside its ``render``. Cycles' engine is the add-on's class
    ``cycles.CyclesRender``, not a documented hook.
    """
    method = _cycles_method("render")
    if method is None:
        return False
    calls = method._visualenv_after
    if after not in calls:
        calls.append(after)
    return True


def unwrap_cycles_render(after: Callable[[Any], None]) -> None:
    """Stop calling `after` at the end of Cycles' renders (:func:`wrap_cycles_render`)."""
    import cycles

    calls = getattr(cycles.CyclesRender.render, "_visualenv_after", [])
    if after in calls:
        calls.remove(after)


#: the moments :func:`mark_cycles_calls` reports, in the order of a render
CYCLES_MARKS = ("update", "update_end", "render", "render_end")


def mark_cycles_calls(mark: Callable[[str], None]) -> Callable[[], None] | None:
    """Have Cycles' engine call ``mark(moment)`` at the start and end of its ``update`` (Blender's data synced into
    Cycles) and its ``render`` (device update, path tracing, the result written back): the moments of
    :data:`CYCLES_MARKS`. Returns the function that stops it; None without the Cycles add-on.

    Why: Blender's render call gives Python its start and end (and ``bpy.app.handlers.render_stats``' status lines in
    between), not where Blender's own depsgraph evaluation ends and Cycles' sync starts; only the engine's methods see that.
    """
    methods = {name: _cycles_method(name) for name in ("update", "render")}
    if any(method is None for method in methods.values()):
        return None

    def marker(moment: str) -> Callable[[Any], None]:
        return lambda engine: mark(moment)

    added: list[tuple[list, Callable[[Any], None]]] = []
    for name, method in methods.items():
        for calls, moment in ((method._visualenv_before, name), (method._visualenv_after, f"{name}_end")):
            call = marker(moment)
            calls.append(call)
            added.append((calls, call))

    def stop() -> None:
        for calls, call in added:
            if call in calls:
                calls.remove(call)

    return stop


# -- Blender's matrix arithmetic ------------------------------------------------------------------------------------
# An instance drawn from numpy's matrices must stand exactly where Blender would put the object (the same pixels as
# a copied object): these compose as Blender does, in float32, with its order of sums.


def mul_m4_m4m4(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` of 4x4 float32 matrices (stacks broadcast), summed as Blender's ``mul_m4_m4m4`` sums (its SSE
    code: the first two products added, the last two added, then the two sums)."""
    terms = a[..., :, :, None] * b[..., None, :, :]  # [..., i, k, j] = a[i, k] * b[k, j]
    return (terms[..., 0, :] + terms[..., 1, :]) + (terms[..., 2, :] + terms[..., 3, :])


def quat_to_mat3(quats: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(M, 3, 3)`` float32 of quaternions ``(M, 4)`` (w, x, y, z) as Blender makes them from an
    object's float32 quaternion: normalised in float32, then its ``quat_to_mat3`` in double."""
    q = quats.astype(np.float32)
    dot = ((q[:, 0] * q[:, 0] + q[:, 1] * q[:, 1]) + q[:, 2] * q[:, 2]) + q[:, 3] * q[:, 3]
    length = np.sqrt(dot)
    q = q * (np.float32(1.0) / np.where(length == 0, np.float32(1.0), length))[:, None]
    q0, q1, q2, q3 = (np.sqrt(2.0) * q.astype(np.float64)).T
    qda, qdb, qdc, qaa, qab, qac, qbb, qbc, qcc = (
        q0 * q1,
        q0 * q2,
        q0 * q3,
        q1 * q1,
        q1 * q2,
        q1 * q3,
        q2 * q2,
        q2 * q3,
        q3 * q3,
    )
    out = np.empty((len(q), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = 1.0 - qbb - qcc, -qdc + qab, qdb + qac
    out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = qdc + qab, 1.0 - qaa - qcc, -qda + qbc
    out[:, 2, 0], out[:, 2, 1], out[:, 2, 2] = -qdb + qac, qda + qbc, 1.0 - qaa - qbb
    return out.astype(np.float32)


def basis_matrices(location: np.ndarray, rotation: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Each object's ``matrix_basis`` ``(N, 4, 4)`` float32 as Blender's ``BKE_object_to_mat4`` computes it from its
    float32 properties: translation @ rotation @ scale. `location` and `scale` ``(N, 3)``; `rotation` ``(N, 3)``
    Euler XYZ angles (Blender's ``eulO_to_mat3``, in double from the float angles) or ``(1, 4)`` one quaternion."""
    n = len(location)
    out = np.zeros((n, 4, 4), dtype=np.float32)
    if rotation.shape[-1] == 4:
        out[:, :3, :3] = quat_to_mat3(rotation)
    else:
        angles = rotation.astype(np.float64)
        ci, cj, ch = np.cos(angles).T
        si, sj, sh = np.sin(angles).T
        cc, cs, sc, ss = ci * ch, ci * sh, si * ch, si * sh
        out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = cj * ch, sj * sc - cs, sj * cc + ss
        out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = cj * sh, sj * ss + cc, sj * cs - sc
        out[:, 2, 0], out[:, 2, 1], out[:, 2, 2] = -sj, cj * si, cj * ci
    out[:, :3, :3] *= scale[:, None, :]
    out[:, :3, 3] = location
    out[:, 3, 3] = 1.0
    return out


# -- render results, one per scene name -----------------------------------------------------------------------------
# Blender keeps one render per scene name (RE_NewSceneRender), holding the buffers of its last frame, in a list it
# never shrinks; removing the scene does not free it (a later render of that name may, not in every process: the
# test counts malloc's bytes). Reusing names alone bounds the list but keeps each name's last frame, which a last 4x4
# render of the emptied scene at close replaces (results/benchmarks/env-rounds-memory.md). So both: names reused, and
# a last tiny frame at close.

#: the names of the scenes renderers build: the first of these that no scene holds
SCENE_NAME = "visualenv-scene-{}"
#: the side of the frame :func:`release_render_result` renders in place of a scene's last one
RELEASE_SIZE = 4


def reusable_scene_name() -> str:
    """A name for a renderer's new scene: the first ``visualenv-scene-<i>`` that no scene has now, so that Blender's
    renders (one per name ever rendered) are as many as the most scenes alive at once, not one per env ever made."""
    import bpy

    check_bpy("reuse of scene names")
    i = 0
    while SCENE_NAME.format(i) in bpy.data.scenes:
        i += 1
    return SCENE_NAME.format(i)


def release_render_result(scene: Any) -> None:
    """Render the scene once more, at 4x4 pixels with nothing in it, before it is removed: the name's render then
    holds a 4x4 frame instead of the scene's last one. Persistent data turned off first frees Cycles' session at
    once (Blender's update of that setting), and the tiny render makes none."""
    import bpy

    for obj in scene.objects:  # nothing to synchronise: the frame is never read
        obj.hide_render = True
    scene.render.use_persistent_data = False
    scene.render.resolution_x = scene.render.resolution_y = RELEASE_SIZE
    scene.render.resolution_percentage = 100
    if scene.render.engine == "CYCLES":
        scene.cycles.samples = 1
        scene.cycles.use_denoising = False
    bpy.ops.render.render(scene=scene.name)


# -- Cycles' CUDA kernels -------------------------------------------------------------------------------------------
# Cycles (intern/cycles/device/cuda/device_impl.cpp, CUDADevice::compile_kernel) loads, in this order:
# path_get("lib/kernel_sm_XY.cubin.zst"), then the closest path_get("lib/kernel_compute_XY.ptx.zst") at or below the
# GPU's architecture (compiled by the driver at the first frame: minutes for its whole kernel), then its own cache of
# kernels compiled with nvcc (path_cache_get("kernels"), $XDG_CACHE_HOME/cycles/kernels), consulted only when no
# shipped PTX fits, which bpy 5.0 always has (compute_75). path_get joins the folder the add-on gives _cycles.init,
# its own; no setting moves "lib" (CYCLES_KERNEL_PATH moves "source", CYCLES_SHADER_PATH "shader"). So the least
# intrusive way to add a binary without writing into bpy: a folder that mirrors the add-on's with links (lib/ linked
# file by file, plus the cached binaries), given to _cycles.init as the add-on does at registration.


def cycles_addon() -> Path | None:
    """The folder of bpy's Cycles add-on (holding ``lib/``, its kernels), found without importing bpy; None without bpy."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        return None
    found = sorted(Path(spec.origin).resolve().parent.glob("*/scripts/addons_core/cycles"))
    return found[0] if found else None


def kernel_cache() -> Path:
    """Where compiled kernels are kept: ``$XDG_CACHE_HOME/visualenv/cycles`` (``~/.cache/visualenv/cycles``)."""
    root = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(root) / "visualenv" / "cycles"


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def cached_kernel(arch: str, ptx: Path, version: str) -> Path:
    """Where the binary for `arch` compiled from `ptx` for bpy `version` is kept: keyed by the version and the PTX's
    SHA-256, under the name Cycles looks for (``bpy-5.0.1/kernel_compute_75-<sha>/kernel_sm_90.cubin.zst``)."""
    stem = ptx.name.removesuffix(".ptx.zst")
    return kernel_cache() / f"bpy-{version}" / f"{stem}-{_digest(ptx)}" / f"kernel_{arch}.cubin.zst"


def source_ptx(arch: str, lib: Path) -> Path | None:
    """The PTX Cycles falls back to for `arch` ('sm_90'): the highest ``kernel_compute_XY`` in `lib` not above it."""
    number = int(arch.split("_")[1])
    found = {
        int(m.group(1)): p
        for p in lib.glob("kernel_compute_*.ptx.zst")
        if (m := re.fullmatch(r"kernel_compute_(\d+)\.ptx\.zst", p.name))
    }
    usable = [n for n in found if n <= number]
    return found[max(usable)] if usable else None


def cached_kernels(addon: Path | None = None) -> dict[str, Path]:
    """The cached binaries Cycles would use here, by architecture: for this bpy, compiled from the PTX it ships now,
    for architectures it ships no binary for."""
    addon = addon or cycles_addon()
    version = bpy_version()
    if addon is None or version is None:
        return {}
    lib = addon / "lib"
    out = {}
    for path in sorted((kernel_cache() / f"bpy-{version}").glob("*/kernel_sm_*.cubin.zst")):
        arch = path.name.removeprefix("kernel_").removesuffix(".cubin.zst")
        ptx = source_ptx(arch, lib)
        if ptx is not None and not (lib / path.name).exists() and path == cached_kernel(arch, ptx, version):
            out[arch] = path
    return out


def cycles_folder_with(kernels: dict[str, Path], addon: Path) -> Path:
    """A folder that is the add-on's as Cycles reads it, plus `kernels` in its ``lib/``: links, made once (under the
    kernel cache, named by what it links) and shared by every process after."""
    key = hashlib.sha256(repr((str(addon), sorted((a, str(p)) for a, p in kernels.items()))).encode()).hexdigest()[:16]
    folder = kernel_cache() / f"bpy-{bpy_version()}" / f"cycles-{key}"
    if folder.is_dir():
        return folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    building = Path(tempfile.mkdtemp(prefix=".cycles-", dir=folder.parent))
    try:
        for entry in addon.iterdir():
            if entry.name != "lib":
                (building / entry.name).symlink_to(entry)
        (building / "lib").mkdir()
        for entry in (addon / "lib").iterdir():
            (building / "lib" / entry.name).symlink_to(entry)
        for arch, path in kernels.items():
            (building / "lib" / f"kernel_{arch}.cubin.zst").symlink_to(path)
        building.rename(folder)
    except OSError:
        if not folder.is_dir():
            raise
    finally:
        shutil.rmtree(building, ignore_errors=True)  # another process made the folder first
    return folder


def point_cycles_at(folder: Path) -> None:
    """Have Cycles read its kernels, shaders and sources from `folder`: what the add-on's ``init`` does with its own."""
    import _cycles  # the add-on's C module, importable once bpy is
    import bpy

    user_path = os.path.dirname(os.path.abspath(bpy.utils.user_resource("CONFIG", path="")))
    _cycles.init(str(folder), user_path, bpy.app.background)


def use_cached_kernels() -> Path | None:
    """Point Cycles at the kernels ``visualenv compile-kernels`` cached for this bpy, if there are any (once a
    process, before its first GPU render); the folder Cycles reads now, or None (nothing cached, or this bpy was not
    checked: the driver then compiles the shipped PTX)."""
    global _pointed, _looked
    if not _looked:
        _looked = True
        addon = cycles_addon()
        kernels = cached_kernels(addon)
        if addon is not None and kernels and check_bpy("cache of compiled CUDA kernels"):
            try:
                folder = cycles_folder_with(kernels, addon)
            except OSError as exc:  # a cache that cannot be written: the driver compiles the PTX, as without a cache
                warnings.warn(
                    f"cannot use the compiled CUDA kernels in {kernel_cache()}: {exc}", RuntimeWarning, stacklevel=2
                )
                return None
            point_cycles_at(folder)
            _pointed = folder
    return _pointed


_looked = False
_pointed: Path | None = None


# -- one face order for bmesh's primitives ------------------------------------------------------------------------


def sort_faces(bm: Any) -> None:
    """Put a BMesh's faces in one order, whatever order the operators that made them left.

    ``bmesh.ops.create_uvsphere`` lists the same faces in an order that varies from process to process, even on one
    thread without address randomisation. Blender sums a vertex's normal over its faces in face order, so a sphere's
    vertex normals, and every pixel that shades them, differed in their last bits from one process to the next
    (results/benchmarks/cross-machine-replay.md). Sorted by their vertices, the faces come out the same everywhere.
    """
    check_bpy("face order")
    bm.verts.index_update()
    for rank, face in enumerate(sorted(bm.faces, key=lambda f: sorted(v.index for v in f.verts))):
        face.index = rank
    bm.faces.sort(key=lambda f: f.index)
    bm.faces.index_update()
