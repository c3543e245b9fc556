"""Build the Blender scene a spec describes: load a .blend, add primitives, meshes, lights, cameras.

Everything is created through ``bpy.data`` and ``bmesh`` (no operators, which
need a window context), except mesh import, which uses Blender's importers
under a context override. :class:`DataTracker` records every datablock that
appears while a scene is built, so the renderer can remove exactly those.

Objects are known by their spec names: Blender renames an object whose name is
taken (``Cart.001`` when another renderer in the process has a ``Cart``), so
:attr:`BuiltScene.objects` maps the spec's (or the .blend file's) names to the
objects themselves.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import bmesh
import bpy
import numpy as np
from mathutils import Matrix, Vector

from visualenv.compat.blender import reusable_scene_name, sort_faces
from visualenv.compat.glibc import release_free_memory
from visualenv.render.blender.scene.blendfile import BlendReadError
from visualenv.render.blender.scene import blendfile
from visualenv.render.blender.runtime.autorun import turn_autorun_off
from visualenv.errors import Diagnostic, SpecError, did_you_mean
from visualenv.files import MAX_IMAGE_PIXELS
from visualenv.render.blender.runtime.log import blender_output, marked
from visualenv.render.terrain import HeightmapError, crater_heights, heightmap_heights, read_heightmap
from visualenv.render.blender.look.materials import fix_uv_coordinates, make_material, make_world
from visualenv.render.plan import (
    CameraObject,
    EmptyObject,
    LightObject,
    MeshObject,
    PrimitiveObject,
    Scene,
    SceneObject,
)
from visualenv.source_map import SourceMap

#: bpy.data collections whose new datablocks a renderer owns
ID_COLLECTIONS = (
    "scenes",
    "objects",
    "meshes",
    "materials",
    "worlds",
    "cameras",
    "lights",
    "images",
    "collections",
    "node_groups",
    "textures",
    "actions",
    "curves",
    "armatures",
    "lattices",
    "grease_pencils",
    "fonts",
    "libraries",
    "lightprobes",
    "particles",
    "pointclouds",
    "volumes",
    "hair_curves",
    "speakers",
    "sounds",
    "texts",
    "cache_files",
    "metaballs",
    "movieclips",
    "masks",
    "linestyles",
    "palettes",
    "paint_curves",
    "brushes",
)
MESH_IMPORTERS = {".obj": "obj", ".stl": "stl", ".ply": "ply", ".glb": "gltf", ".gltf": "gltf"}


class DataTracker:
    """Remembers which datablocks existed at construction; :meth:`new` lists the ones added since."""

    def __init__(self) -> None:
        self._before = {name: {i.as_pointer() for i in coll} for name, coll in self._collections()}

    @staticmethod
    def _collections() -> list[tuple[str, Any]]:
        return [(n, getattr(bpy.data, n)) for n in ID_COLLECTIONS if hasattr(bpy.data, n)]

    def new(self) -> list[Any]:
        out: list[Any] = []
        for name, coll in self._collections():
            before = self._before.get(name, set())
            out.extend(i for i in coll if i.as_pointer() not in before)
        return out


def is_alive(datablock: Any) -> bool:
    """Whether `datablock` was not removed (Blender invalidates the Python object of a removed one)."""
    try:
        datablock.name  # noqa: B018 - raises ReferenceError once removed
    except ReferenceError:
        return False
    return True


def remove_ids(ids: list[Any]) -> None:
    """Remove datablocks that still exist (scenes one by one, the rest in one batch)."""
    alive = [datablock for datablock in ids if is_alive(datablock)]
    scenes = [d for d in alive if isinstance(d, bpy.types.Scene)]
    others = [d for d in alive if not isinstance(d, bpy.types.Scene)]
    for scene in scenes:
        if len(bpy.data.scenes) > 1:
            bpy.data.scenes.remove(scene)
    if others:
        bpy.data.batch_remove(others)
    release_free_memory()  # what the scene's renders freed into the render threads' arenas


@dataclass
class BuiltScene:
    scene: Any
    collection: Any
    objects: dict[str, Any] = field(default_factory=dict)  # spec/file name -> object
    max_image_pixels: int = MAX_IMAGE_PIXELS  # the spec's scene.max_image_pixels: textures' and heightmaps' limit


def build_scene(spec: Scene, *, base_dir: Path, source: SourceMap, prefix: str) -> BuiltScene:
    """The scene: a scene of the .blend (appended) or a new one, plus every declared object.

    What Blender prints meanwhile (importer timings, its own read errors) is
    dropped when the build succeeds and follows the error, marked, when it fails.
    """
    with blender_output() as output:
        try:
            return _build_scene(spec, base_dir=base_dir, source=source, prefix=prefix)
        except SpecError as exc:
            error = exc
    said = "\n".join(d.message for d in error.diagnostics)
    raise SpecError(error.diagnostics, [*error.notes, *marked(output.lines, said)]) from None


def _build_scene(spec: Scene, *, base_dir: Path, source: SourceMap, prefix: str) -> BuiltScene:
    if spec.file:
        scene, objects = load_blend(spec.file, base_dir=base_dir, source=source, scene_name=spec.file_scene)
        scene.name = reusable_scene_name()
    else:
        scene, objects = bpy.data.scenes.new(reusable_scene_name()), {}
    collection = bpy.data.collections.new(f"{prefix}-objects")
    scene.collection.children.link(collection)
    built = BuiltScene(scene, collection, objects, spec.max_image_pixels)
    problems: list[Diagnostic] = []
    for name, obj_spec in spec.objects.items():
        try:
            built.objects[name] = _build_object(name, obj_spec, built, base_dir=base_dir, source=source)
        except SpecError as exc:
            problems.extend(exc.diagnostics)
    for name, obj_spec in spec.objects.items():
        if obj_spec.parent is None or name not in built.objects:
            continue
        parent = built.objects.get(obj_spec.parent)
        if parent is None:
            problems.append(
                source.diagnostic(
                    ("scene", "objects", name, "parent"),
                    f"no object '{obj_spec.parent}' in the scene"
                    + did_you_mean(obj_spec.parent, built.objects).replace("names:", "objects:"),
                )
            )
            continue
        obj, chain = built.objects[name], [parent]
        while chain[-1] is not None and chain[-1] is not obj:
            chain.append(chain[-1].parent)
        if chain[-1] is obj:  # Blender would take the loop (or refuse only the object itself, with a TypeError)
            loop = (
                " -> ".join([name, *(o.name for o in chain[:-1]), name]) if parent is not obj else f"{name} -> {name}"
            )
            problems.append(
                source.diagnostic(
                    ("scene", "objects", name, "parent"),
                    f"parents form a loop ({loop}): an object cannot be its own ancestor",
                )
            )
            continue
        obj.parent = parent
    if problems:
        raise SpecError(problems)
    for name, obj_spec in spec.objects.items():
        if isinstance(obj_spec, CameraObject) and obj_spec.look_at is not None:
            aim(built.objects[name], obj_spec.look_at)  # after parenting: the target is a world point
    if spec.world is not None or scene.world is None:
        scene.world = make_world(
            f"{prefix}-world",
            spec.world or spec.default_world,
            _keep,
            base_dir=base_dir,
            source=source,
            max_pixels=spec.max_image_pixels,
        )
    return built


def _keep(datablock: Any) -> Any:
    return datablock


# -- .blend files ------------------------------------------------------------------------------------


def load_blend(
    file: str, *, base_dir: Path, source: SourceMap, scene_name: str | None = None
) -> tuple[Any, dict[str, Any]]:
    """Append one scene of a .blend, `scene_name` or its only one (the current file stays as it is); name -> object by the file's names."""
    path = (base_dir / file).resolve()
    where = ("scene", "file")
    if not path.is_file():
        raise SpecError(
            [source.diagnostic(where, "scene file " + ("is a folder" if path.is_dir() else "not found") + f": {path}")]
        )
    if not blendfile.is_blend_file(path):
        raise SpecError([source.diagnostic(where, f"not a Blender file: {path} (a .blend saved by Blender is needed)")])
    _check_readable(path, source)
    turn_autorun_off()  # the file's drivers come with its objects: they must find auto-run off when they first run
    try:
        with bpy.data.libraries.load(str(path), link=False) as (data_from, data_to):
            scene_names = list(data_from.scenes)
            object_names = list(data_from.objects)
            wanted = scene_name if scene_name is not None else (scene_names[0] if len(scene_names) == 1 else None)
            if wanted in scene_names:
                data_to.scenes = [wanted]
                data_to.objects = list(object_names)  # Blender swaps the names for the objects in place
    except (OSError, RuntimeError, ValueError) as exc:
        raise SpecError([source.diagnostic(where, f"cannot read {path} as a .blend file: {exc}")]) from None
    if scene_name is not None and scene_name not in scene_names:
        raise SpecError(
            [
                source.diagnostic(
                    ("scene", "file_scene"),
                    f"{path} has no scene '{scene_name}'"
                    + did_you_mean(scene_name, scene_names).replace("names:", "scenes:"),
                )
            ]
        )
    if scene_name is None and len(scene_names) > 1:  # the file's order says nothing about which one was meant
        raise SpecError(
            [
                source.diagnostic(
                    where,
                    f"{path} has {len(scene_names)} scenes ({', '.join(scene_names)}): "
                    "choose one with scene.file_scene",
                )
            ]
        )
    if not scene_names or not data_to.scenes or data_to.scenes[0] is None:
        raise SpecError([source.diagnostic(where, f"{path} has no scene")])
    scene = data_to.scenes[0]
    in_scene = {o.as_pointer() for o in scene.objects}
    by_name = {
        name: obj
        for name, obj in zip(object_names, data_to.objects)
        if obj is not None and obj.as_pointer() in in_scene
    }
    return scene, by_name


def _check_readable(path: Path, source: SourceMap) -> None:
    """Read the file in a child process first (a file that crashes Blender is an error, not a dead process).

    Policy: a missing linked library is an error (its objects would be absent without a word); a
    missing image file is a warning (Blender renders it magenta; the env still works).
    """
    where = ("scene", "file")
    try:
        info = blendfile.describe(path)
    except BlendReadError as exc:
        raise SpecError([source.diagnostic(where, str(exc))]) from None
    missing = [lib for lib in info["libraries"] if not lib["found"]]
    if missing:
        raise SpecError(
            [
                source.diagnostic(
                    where,
                    f"linked library not found: {lib['path']} (resolved: {_resolve_blender_path(lib['path'], path)}), "
                    f"the source of {', '.join(lib['uses']) or 'no data'}: put it back, or make the data local in Blender "
                    "(Object > Relations > Make Local) and save",
                )
                for lib in missing
            ]
        )
    for image in info["missing_images"]:
        warnings.warn(
            str(
                source.diagnostic(
                    where,
                    f"image file not found: {image['path']} (image '{image['name']}' in {path.name}) "
                    "renders magenta: put the file back, or pack it in Blender (File > External Data > Pack Resources)",
                )
            ),
            RuntimeWarning,
            stacklevel=4,
        )


def _resolve_blender_path(blender_path: str, blend: Path) -> Path:
    """A path as Blender stores it ('//' is the .blend's folder)."""
    return (blend.parent / blender_path[2:]).resolve() if blender_path.startswith("//") else Path(blender_path)


# -- objects -----------------------------------------------------------------------------------------


def _build_object(name: str, spec: SceneObject, built: BuiltScene, *, base_dir: Path, source: SourceMap) -> Any:
    path = ("scene", "objects", name)
    if isinstance(spec, PrimitiveObject):
        heights = None
        if spec.primitive == "terrain" and spec.heightmap is not None:
            try:
                heights = read_heightmap((base_dir / spec.heightmap).resolve(), built.max_image_pixels)
            except HeightmapError as exc:
                raise SpecError([source.diagnostic(path + ("heightmap",), str(exc))]) from None
        mesh = bpy.data.meshes.new(name)
        _primitive_mesh(mesh, spec, heights)
        obj = bpy.data.objects.new(name, mesh)
        mat = make_material(
            name,
            spec.material,
            base_dir=base_dir,
            source=source,
            path=path + ("material",),
            track=_keep,
            max_pixels=built.max_image_pixels,
        )
        mesh.materials.append(mat)
        fix_uv_coordinates(mat, mesh)
    elif isinstance(spec, MeshObject):
        obj = _import_mesh(name, spec, built, base_dir=base_dir, source=source)
    elif isinstance(spec, LightObject):
        light = bpy.data.lights.new(name, spec.light.upper())
        light.energy = spec.strength
        light.color = spec.color[:3]
        if spec.light == "spot":
            light.spot_size = spec.spot_size
        if spec.light == "area":
            light.size = spec.size
        elif spec.light in ("point", "spot"):
            light.shadow_soft_size = spec.size
        obj = bpy.data.objects.new(name, light)
    elif isinstance(spec, CameraObject):
        cam = bpy.data.cameras.new(name)
        cam.type = "PERSP" if spec.camera == "perspective" else "ORTHO"
        cam.lens = spec.lens
        cam.sensor_fit = "HORIZONTAL"
        cam.sensor_width = spec.sensor_width
        cam.ortho_scale = spec.ortho_scale
        cam.clip_start = spec.clip_start
        cam.clip_end = spec.clip_end
        obj = bpy.data.objects.new(name, cam)
    elif isinstance(spec, EmptyObject):
        obj = bpy.data.objects.new(name, None)
    else:  # pragma: no cover - the models allow nothing else
        raise TypeError(f"unknown object kind: {spec!r}")
    if obj.name not in built.collection.objects:
        built.collection.objects.link(obj)
    obj.location = spec.location
    obj.rotation_mode = "XYZ"
    obj.rotation_euler = spec.rotation
    obj.scale = (spec.scale,) * 3 if isinstance(spec.scale, (int, float)) else spec.scale
    obj.hide_render = not spec.visible
    return obj


def aim(obj: Any, target: Any) -> None:
    """Point the object's -Z axis at the world point `target` (Y up), as Blender's Track To constraint does."""
    parent = _parent_frame(obj)
    direction = Vector(target) - parent @ obj.location
    if direction.length_squared < 1e-18:
        return
    world = direction.to_track_quat("-Z", "Y")
    obj.rotation_euler = (parent.to_quaternion().inverted() @ world).to_euler("XYZ")


def with_ancestors(obj: Any, stop: Any = None) -> Iterator[Any]:
    """The object, its parent, its parent's parent... up to (not including) `stop`, or to the root."""
    while obj is not None and obj != stop:
        yield obj
        obj = obj.parent


def _parent_frame(obj: Any) -> Matrix:
    """The matrix that takes `obj`'s own location and rotation to world space.

    Built from the parents' current location, rotation and scale rather than from
    their matrix_world, which is stale until Blender next evaluates the scene (a
    parent moved by a binding in this same render).
    """
    if obj.parent is None:
        return Matrix.Identity(4)
    parent = obj.parent
    return _parent_frame(parent) @ parent.matrix_basis @ obj.matrix_parent_inverse


def _primitive_mesh(mesh: Any, spec: PrimitiveObject, heights: np.ndarray | None = None) -> None:
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    kind, n = spec.primitive, spec.segments
    size = spec.size if isinstance(spec.size, tuple) else (spec.size,) * 3
    if kind == "cube":
        bmesh.ops.create_cube(bm, size=1.0, calc_uvs=True)
        bmesh.ops.scale(bm, vec=Vector(size), verts=bm.verts)
    elif kind == "plane":
        bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=0.5, calc_uvs=True)
        bmesh.ops.scale(bm, vec=Vector((size[0], size[1], 1.0)), verts=bm.verts)
    elif kind == "terrain":
        _terrain(bm, spec, (size[0], size[1], size[2]), heights)
    elif kind == "sphere":
        bmesh.ops.create_uvsphere(bm, u_segments=n, v_segments=max(3, n // 2), radius=spec.radius, calc_uvs=True)
    elif kind in ("cylinder", "cone"):
        top = spec.radius if kind == "cylinder" else 0.0
        bmesh.ops.create_cone(
            bm,
            cap_ends=True,
            cap_tris=False,
            segments=n,
            radius1=spec.radius,
            radius2=top,
            depth=spec.depth,
            calc_uvs=True,
        )
    elif kind == "disk":
        bmesh.ops.create_circle(bm, cap_ends=True, segments=n, radius=spec.radius, calc_uvs=True)
    elif kind == "torus":
        _torus(bm, spec.radius, spec.thickness, n, max(6, n // 3))
    elif kind == "ring":
        _ring(bm, spec.radius, max(spec.radius - spec.thickness, spec.radius * 0.01), n)
    if spec.origin == "bottom" and bm.verts:
        low = min(v.co.z for v in bm.verts)
        bmesh.ops.translate(bm, vec=Vector((0.0, 0.0, -low)), verts=bm.verts)
    for face in bm.faces:
        face.smooth = spec.smooth
    if kind == "sphere":
        sort_faces(bm)
    bm.to_mesh(mesh)
    bm.free()


def _terrain(bm: Any, spec: PrimitiveObject, size: tuple[float, float, float], heights: np.ndarray | None) -> None:
    """A flat grid of `segments` cells a side, its vertices raised to the heightmap's relief (if any) and sunk by the craters."""
    bmesh.ops.create_grid(bm, x_segments=spec.segments, y_segments=spec.segments, size=0.5, calc_uvs=True)
    extent = (size[0], size[1])
    bmesh.ops.scale(bm, vec=Vector((extent[0], extent[1], 1.0)), verts=bm.verts)
    if spec.craters is None and heights is None:
        return
    verts = list(bm.verts)
    xy = np.array([(v.co.x, v.co.y) for v in verts])
    z = np.zeros(len(verts))
    if heights is not None:
        z += heightmap_heights(xy[:, 0], xy[:, 1], heights, size)
    if spec.craters is not None:
        z += crater_heights(xy[:, 0], xy[:, 1], spec.craters, extent)
    for vert, height in zip(verts, z):
        vert.co.z = float(height)
    bm.normal_update()


def _torus(bm: Any, major: float, minor: float, major_segments: int, minor_segments: int) -> None:
    rings = []
    for i in range(major_segments):
        a = 2 * math.pi * i / major_segments
        ring = []
        for j in range(minor_segments):
            b = 2 * math.pi * j / minor_segments
            r = major + minor * math.cos(b)
            ring.append(bm.verts.new((r * math.cos(a), r * math.sin(a), minor * math.sin(b))))
        rings.append(ring)
    for i in range(major_segments):
        for j in range(minor_segments):
            i2, j2 = (i + 1) % major_segments, (j + 1) % minor_segments
            bm.faces.new((rings[i][j], rings[i2][j], rings[i2][j2], rings[i][j2]))


def _ring(bm: Any, outer: float, inner: float, segments: int) -> None:
    outs, ins = [], []
    for i in range(segments):
        a = 2 * math.pi * i / segments
        outs.append(bm.verts.new((outer * math.cos(a), outer * math.sin(a), 0.0)))
        ins.append(bm.verts.new((inner * math.cos(a), inner * math.sin(a), 0.0)))
    for i in range(segments):
        k = (i + 1) % segments
        bm.faces.new((ins[i], outs[i], outs[k], ins[k]))


def _import_mesh(name: str, spec: MeshObject, built: BuiltScene, *, base_dir: Path, source: SourceMap) -> Any:
    where = ("scene", "objects", name, "mesh")
    path = (base_dir / spec.mesh).resolve()
    kind = MESH_IMPORTERS.get(path.suffix.lower())
    if kind is None:
        raise SpecError(
            [
                source.diagnostic(
                    where, f"unsupported mesh format '{path.suffix}': use one of {', '.join(MESH_IMPORTERS)}"
                )
            ]
        )
    if not path.is_file():
        raise SpecError(
            [source.diagnostic(where, "mesh file " + ("is a folder" if path.is_dir() else "not found") + f": {path}")]
        )
    scene = built.scene
    before = {o.as_pointer() for o in bpy.data.objects}
    importer: Callable[..., Any] = {
        "obj": bpy.ops.wm.obj_import,
        "stl": bpy.ops.wm.stl_import,
        "ply": bpy.ops.wm.ply_import,
        "gltf": bpy.ops.import_scene.gltf,
    }[kind]
    layer = scene.view_layers[0]
    try:
        with bpy.context.temp_override(scene=scene, view_layer=layer, collection=built.collection):
            result = importer(filepath=str(path))
    except (RuntimeError, TypeError) as exc:
        raise SpecError([source.diagnostic(where, f"cannot import {path}: {' '.join(str(exc).split())}")]) from None
    new = [o for o in bpy.data.objects if o.as_pointer() not in before]
    if "FINISHED" not in result or not new:
        raise SpecError([source.diagnostic(where, f"{path} has no mesh to import")])
    for obj in new:
        for coll in list(obj.users_collection):
            coll.objects.unlink(obj)
        built.collection.objects.link(obj)
    roots = [o for o in new if o.parent is None]
    if len(roots) == 1:
        obj = roots[0]
        obj.name = name
    else:
        obj = bpy.data.objects.new(name, None)
        built.collection.objects.link(obj)
        for child in roots:
            child.parent = obj
    if spec.material is not None:
        mat = make_material(
            name,
            spec.material,
            base_dir=base_dir,
            source=source,
            path=("scene", "objects", name, "material"),
            track=_keep,
            max_pixels=built.max_image_pixels,
        )
        for o in new:
            if o.type == "MESH":
                o.data.materials.clear()
                o.data.materials.append(mat)
                fix_uv_coordinates(mat, o.data)
    # the spec's location/rotation/scale replace the imported root's transform
    return obj
