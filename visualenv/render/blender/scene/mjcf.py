"""An MJCF model's geoms, lights and cameras as Blender objects, posed from MuJoCo's arrays every step.

Each body that has geoms (or a camera) becomes an empty; its geoms are meshes
parented to it at their fixed offsets, so a step writes one location and one
quaternion per moving body (rows of ``xpos`` and ``xquat``) and nothing per geom.
Cameras take ``cam_xpos`` and ``cam_xmat`` as MuJoCo computes them, so fixed,
``track`` and ``trackcom`` cameras move as in MuJoCo. A textured geom's mesh
gets a UV map with MuJoCo's texture coordinates (:mod:`visualenv.physics.texcoords`)
and its material reads the texture's pixels, times the geom's colour. Geoms keep their MuJoCo
names (objects a spec can refer to); bodies are ``body:<name>``; the visible sites are drawn as
geoms of their shape, ``site:<name>``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import bmesh
import bpy
import numpy as np
from mathutils import Matrix, Quaternion, Vector

from visualenv.compat.blender import sort_faces
from visualenv.physics.scene import GeomShape, LightInfo, PhysicsScene
from visualenv.physics.tendons import TendonShape, tendon_path
from visualenv.physics.texcoords import cube_uv, planar_uv
from visualenv.render.blender.look.materials import (
    MUJOCO_MATERIAL,
    make_material,
    show_skybox,
    tint_image,
    world_writer,
)
from visualenv.render.blender.look.mujoco import ambient, light_data, light_material
from visualenv.render.plan import Material

#: round shapes' segments: enough for smooth silhouettes at observation sizes
SEGMENTS = 24


#: a custom property of a tendon's segment: its scale follows the state, so a batch copies it (never an instance)
STRETCHED = "visualenv_stretched"


@dataclass
class PoseWriter:
    """Writes MuJoCo's poses into the objects: the moving bodies' empties, the model's cameras and lights, and each
    tendon segment's cylinder stretched between its two points."""

    bodies: list[tuple[int, Any]]  # (body index, empty) of the moving bodies
    cameras: list[Any]  # camera objects by MuJoCo camera index
    lights: list[Any]  # light objects by MuJoCo light index (a light on a body, or tracking one, moves)
    #: each drawn tendon, the unit cylinders (along z, centred) of its segments stretched along its path, their names
    tendons: list[tuple[TendonShape, list[Any], list[str]]]
    # their names in BuiltScene.objects: bodies, cameras, lights
    keys: tuple[list[str], list[str], list[str]] = ([], [], [])

    def for_objects(self, objects: dict[str, Any]) -> "PoseWriter":
        """The same writer for another copy of the scene (a batch's env k), its objects found by name."""
        bodies, cameras, lights = self.keys
        return PoseWriter(
            [(i, objects[key]) for (i, _), key in zip(self.bodies, bodies)],
            [objects[k] for k in cameras],
            [objects[k] for k in lights],
            [(tendon, [objects[k] for k in names], names) for tendon, _, names in self.tendons],
            self.keys,
        )

    def without(self, removed: set[int], keep_cameras: bool) -> "PoseWriter":
        """The same writer less the objects in `removed` (pointers: in a batch, objects drawn as instances, or the
        originals that another copy shares), cameras kept where `keep_cameras`."""
        bodies = [j for j, (_, e) in enumerate(self.bodies) if e.as_pointer() not in removed]
        cameras = [j for j, c in enumerate(self.cameras) if keep_cameras or c.as_pointer() not in removed]
        lights = [j for j, light in enumerate(self.lights) if light.as_pointer() not in removed]
        keys = tuple(
            [names[j] for j in kept] if names else [] for names, kept in zip(self.keys, (bodies, cameras, lights))
        )
        return PoseWriter(
            [self.bodies[j] for j in bodies],
            [self.cameras[j] for j in cameras],
            [self.lights[j] for j in lights],
            [t for t in self.tendons if t[1][0].as_pointer() not in removed],  # its segments all copied, or all shared
            keys,  # type: ignore[arg-type]
        )

    @property
    def empty(self) -> bool:
        """Whether it writes nothing."""
        return not (self.bodies or self.cameras or self.lights or self.tendons)

    def write(
        self,
        xpos: np.ndarray,
        xquat: np.ndarray,
        cam_xpos: np.ndarray,
        cam_xmat: np.ndarray,
        light_xpos: np.ndarray | None = None,
        light_xdir: np.ndarray | None = None,
    ) -> None:
        if self.bodies:
            rows = [i for i, _ in self.bodies]
            positions, quats = xpos[rows].tolist(), xquat[rows].tolist()
            for (_, empty), p, q in zip(self.bodies, positions, quats):
                empty.location = p
                empty.rotation_quaternion = q
        for i, cam in enumerate(self.cameras):
            cam.location = cam_xpos[i].tolist()
            cam.rotation_quaternion = Matrix(cam_xmat[i].reshape(3, 3).tolist()).to_quaternion()
        if light_xpos is not None and light_xdir is not None:
            for i, light in enumerate(self.lights):
                light.location = light_xpos[i].tolist()
                light.rotation_quaternion = Vector(light_xdir[i].tolist()).to_track_quat("-Z", "Y")
        for tendon, cylinders, _ in self.tendons:
            draw_tendon(tendon, cylinders, xpos, xquat)


#: the name suffix of a mesh's second user (:func:`keep_instanced`)
SECOND_USER = " (instanced)"


def keep_instanced(scene: Any) -> None:
    """Give each mesh of `scene` whose data has one user a second user no ray can hit (scaled to nothing, seen by
    shadow rays only), so that Cycles draws every mesh as an instance of its own acceleration structure.

    Cycles applies the transform of a mesh used once to its vertices and builds the mesh into the scene's top-level
    structure, which it builds anew whenever anything moves: each step then rebuilds every such mesh, moving or not.
    An instanced mesh keeps its own structure and only the top level is rebuilt (``visualenv bench --phases``,
    column bvh). An object seen by no ray at all is not handed to Cycles, hence the shadow rays. An object with
    modifiers draws its own evaluated mesh (a batch's instancer draws instances): it is left as it is.
    """
    for obj in list(scene.objects):
        if obj.type != "MESH" or obj.data.users != 1 or obj.hide_render or obj.modifiers:
            continue
        second = bpy.data.objects.new(obj.name + SECOND_USER, obj.data)
        second.scale = (0.0, 0.0, 0.0)
        second.visible_camera = second.visible_diffuse = second.visible_glossy = False
        second.visible_transmission = second.visible_volume_scatter = False
        for collection in obj.users_collection:
            collection.objects.link(second)


def draw_tendon(tendon: TendonShape, cylinders: list[Any], xpos: np.ndarray, xquat: np.ndarray) -> None:
    """The tendon's path from its sites' bodies' poses (:func:`~visualenv.physics.tendons.tendon_path`), a cylinder
    stretched along each segment; the cylinders a shorter path leaves over are shrunk to nothing at its end."""
    sites = np.array([xpos[body] + _rotated(xquat[body], offset) for body, offset in tendon.points], dtype=np.float64)
    path = [Vector(p) for p in tendon_path(tendon, sites).tolist()]
    for k, cylinder in enumerate(cylinders):
        start, end = (path[k], path[k + 1]) if k + 1 < len(path) else (path[-1], path[-1])
        axis = end - start
        cylinder.location = (start + end) / 2
        cylinder.rotation_quaternion = axis.to_track_quat("Z", "Y") if axis.length > 0 else Quaternion()
        cylinder.scale = (1.0, 1.0, axis.length)


def _rotated(quat: np.ndarray, offset: tuple[float, float, float]) -> np.ndarray:
    """`offset` rotated by the unit quaternion w, x, y, z."""
    w, u = float(quat[0]), np.asarray(quat[1:], dtype=np.float64)
    v = np.asarray(offset, dtype=np.float64)
    return v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))


def build_physics_objects(
    scene_data: PhysicsScene, built: Any, *, base_dir: Any, source: Any, add_light: bool, material: Material
) -> PoseWriter:
    """Every drawable geom, light and camera of the model in `built`'s collection (names added to built.objects).

    An object the spec declares (or its .blend holds) under a body's name stands for
    that body: it takes the body's pose (its origin at the body's frame) and the
    body's own geoms are not drawn. A geom's material is `material` (the spec's default) in its colour.
    """
    collection = built.collection
    empties: dict[int, Any] = {}
    #: bodies the spec (or its .blend) draws itself: an object named as the body takes the body's pose, its geoms are not drawn
    own = {b: built.objects[name] for b, name in enumerate(scene_data.body_names) if b > 0 and name in built.objects}

    def empty_of(body: int) -> Any:
        if body not in empties:
            obj = own.get(body)
            if obj is None:
                obj = bpy.data.objects.new(f"body:{scene_data.body_names[body]}", None)
                collection.objects.link(obj)
            obj.rotation_mode = "QUATERNION"
            obj.location = scene_data.body_pos[body].tolist()
            obj.rotation_quaternion = scene_data.body_quat[body].tolist()
            empties[body] = obj
            # a batch finds each copy's empty by this name
            built.objects.setdefault(f"body:{scene_data.body_names[body]}", obj)
        return empties[body]

    for body in own:
        empty_of(body)
    images: dict[int, Any] = {}  # by MuJoCo texture: geoms sharing a texture share its image
    as_mujoco = scene_data.look == "mujoco"  # lit as MuJoCo's renderer lights it (look/mujoco.py)
    lighting = (scene_data.headlight, ambient(scene_data)) if as_mujoco else None

    def drawn(shape: GeomShape) -> Any:
        """The shape's object in the collection (named as the shape in built.objects), lit as the look lights it."""
        obj = _geom_object(
            shape, base_dir=base_dir, source=source, images=images, split_caps=as_mujoco, material=material
        )
        if lighting is not None:
            light_material(
                obj.data.materials[0],
                *lighting,
                emission=shape.emission,
                specular=shape.specular,
                shininess=shape.shininess,
            )
        collection.objects.link(obj)
        built.objects.setdefault(shape.name, obj)
        return obj

    for geom in (*scene_data.geoms, *scene_data.sites):  # a site is drawn as a geom of its shape (named site:<name>)
        if geom.body in own:
            continue
        obj = drawn(geom)
        obj.parent = empty_of(geom.body)
    tendons = []
    for tendon in scene_data.tendons:  # a unit cylinder per segment, stretched along its path at every write
        cylinders, names = [], []
        for k in range(tendon.segments):
            shape = GeomShape(
                f"{tendon.name}:{k}",
                "cylinder",
                0,
                (tendon.width, 0.5, 0.0),
                (0.0, 0.0, 0.0),
                (1.0, 0.0, 0.0, 0.0),
                tendon.rgba,
                emission=tendon.emission,
                specular=tendon.specular,
                shininess=tendon.shininess,
            )
            obj = drawn(shape)
            obj[STRETCHED] = True
            cylinders.append(obj)
            names.append(shape.name)
        draw_tendon(tendon, cylinders, scene_data.body_pos, scene_data.body_quat)
        tendons.append((tendon, cylinders, names))
    lights = []
    for light in scene_data.lights:
        data = light_data(light) if as_mujoco else _physical_light(light)
        obj = bpy.data.objects.new(light.name, data)
        collection.objects.link(obj)
        obj.location = light.pos
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = Vector(light.direction).to_track_quat("-Z", "Y")
        built.objects.setdefault(light.name, obj)
        lights.append(obj)
    # MuJoCo lights a model without lights by its headlight; a sun from above and in front stands in
    if add_light and not as_mujoco:
        sun = bpy.data.objects.new("mujoco-headlight", bpy.data.lights.new("mujoco-headlight", "SUN"))
        sun.data.energy = 3.0
        sun.rotation_euler = (0.6, 0.0, 0.3)
        collection.objects.link(sun)
    cameras = []
    for cam_info in scene_data.cameras:
        cam = bpy.data.cameras.new(cam_info.name)
        cam.sensor_fit = "VERTICAL"
        cam.angle_y = math.radians(cam_info.fovy)
        cam.clip_start, cam.clip_end = 0.01, 100.0
        obj = bpy.data.objects.new(cam_info.name, cam)
        obj.rotation_mode = "QUATERNION"
        # MuJoCo's pose at qpos0: a batch's tiles camera takes a fixed camera's pose when built
        obj.location = cam_info.pos
        obj.rotation_quaternion = cam_info.quat
        collection.objects.link(obj)
        built.objects.setdefault(cam_info.name, obj)
        cameras.append(obj)
    moving = [(int(b), empties[int(b)]) for b in scene_data.moving if int(b) in empties]
    keys = (
        [f"body:{scene_data.body_names[b]}" for b, _ in moving],
        [c.name for c in scene_data.cameras],
        [light.name for light in scene_data.lights],
    )
    return PoseWriter(moving, cameras, lights, tendons, keys)


def _physical_light(light: LightInfo) -> Any:
    """The model's light as a Blender light of its colour (physics.look: physical): a sun, or a spot that falls off with distance."""
    data = bpy.data.lights.new(light.name, "SUN" if light.directional else "SPOT")
    data.color = light.diffuse
    data.energy = 3.0 * max(light.diffuse) if light.directional else 300.0 * max(light.diffuse)
    if not light.directional:
        data.spot_size = min(math.radians(2 * light.cutoff), math.pi)
    return data


def show_model_sky(scene_data: PhysicsScene, world: Any) -> None:
    """The model's skybox behind the scene (seen by the camera, lighting nothing), when it has one; without one, in
    MuJoCo's look, black (MuJoCo clears its image to black)."""
    if world is None or world.node_tree is None:
        return
    if scene_data.sky is None:
        write = world_writer(world, "color")
        if scene_data.look == "mujoco" and not isinstance(write, str):
            write((0.0, 0.0, 0.0))
        return
    show_skybox(world, _packed_image("mjcf-skybox", scene_data.sky))


def _texture_image(geom: GeomShape, images: dict[int, Any]) -> Any:
    """The Blender image of the geom's MuJoCo texture, made once per texture from its pixels."""
    assert geom.texture is not None
    if geom.texture_id not in images:
        images[geom.texture_id] = _packed_image(f"mjcf-texture-{geom.texture_id}", geom.texture)
    return images[geom.texture_id]


def _packed_image(name: str, pixels: np.ndarray) -> Any:
    """A Blender image of `pixels` ((h, w, 4) floats, bottom row first), packed: it has no file."""
    h, w = pixels.shape[:2]
    image = bpy.data.images.new(name, w, h, alpha=True)
    image.pixels.foreach_set(pixels.reshape(-1))
    image.pack()
    return image


def _shape(bm: Any, geom: GeomShape, split_caps: bool) -> tuple[np.ndarray, list[int]]:
    """Builds the geom's surface in `bm` (its own frame, metres): a textured geom's vertices' MuJoCo object coordinates
    (texcoords.py; none without a texture), and for a mesh the MuJoCo face of each polygon made (a duplicate face is skipped).
    `split_caps`: a cylinder's flat ends get vertices of their own, so that its smooth side's normals point straight out."""
    size = geom.size
    # a capsule's end spheres and their centres: MuJoCo textures each about its centre
    caps: list[tuple[list[Any], float]] = []
    made: list[int] = []
    if geom.kind == "plane":
        bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=1.0)
        bmesh.ops.scale(bm, vec=Vector((size[0], size[1], 1.0)), verts=bm.verts)
    elif geom.kind == "box":
        bmesh.ops.create_cube(bm, size=2.0)
        bmesh.ops.scale(bm, vec=Vector(size), verts=bm.verts)
    elif geom.kind in ("sphere", "ellipsoid"):
        bmesh.ops.create_uvsphere(
            bm, u_segments=SEGMENTS, v_segments=SEGMENTS // 2, radius=1.0 if geom.kind == "ellipsoid" else size[0]
        )
        if geom.kind == "ellipsoid":
            bmesh.ops.scale(bm, vec=Vector(size), verts=bm.verts)
    elif geom.kind in ("cylinder", "capsule"):
        bmesh.ops.create_cone(bm, cap_ends=True, segments=SEGMENTS, radius1=size[0], radius2=size[0], depth=2 * size[1])
        if split_caps:  # Cycles smooths by vertex normals: a rim vertex shared with an end tilts the side's normals up to 45 degrees
            bmesh.ops.split_edges(bm, edges=[e for e in bm.edges if any(len(f.verts) > 4 for f in e.link_faces)])
        if geom.kind == "capsule":  # a cylinder and two spheres: the overlap does not show
            for z in (-size[1], size[1]):
                made_sphere = bmesh.ops.create_uvsphere(
                    bm,
                    u_segments=SEGMENTS,
                    v_segments=SEGMENTS // 2,
                    radius=size[0],
                    matrix=Matrix.Translation((0, 0, z)),
                )
                caps.append((made_sphere["verts"], z))
    elif geom.kind == "mesh" and geom.vertices is not None and geom.faces is not None:
        verts = [bm.verts.new(v) for v in geom.vertices.tolist()]
        for f, face in enumerate(geom.faces.tolist()):
            try:
                bm.faces.new([verts[i] for i in face])
                made.append(f)
            except ValueError:  # a duplicate face: MuJoCo keeps it, Blender cannot
                pass
    if geom.texture is None:  # nothing reads the object coordinates
        return np.zeros((0, 3)), made
    bm.verts.index_update()
    if geom.kind == "mesh" and geom.vertices is not None:  # made in this order, at the geom's own coordinates
        points = np.asarray(geom.vertices, dtype=np.float64).reshape(-1, 3)
    else:
        points = np.array([v.co[:] for v in bm.verts], dtype=np.float64).reshape(-1, 3) / np.array(
            geom.unit
        ) + np.array(geom.texorigin)
    for sphere, z in caps:  # MuJoCo's caps are unit hemispheres about their own centres, scaled by the radius
        rows = [v.index for v in sphere]
        points[rows] = (np.array([v.co[:] for v in sphere]) - (0.0, 0.0, z)) / size[0]
    return points, made


def _uv_map(mesh: Any, geom: GeomShape, points: np.ndarray, made: list[int]) -> None:
    """The UV map by which the mesh reads the geom's texture as MuJoCo maps it (texcoords.py), one UV per face corner."""
    loop_vertex = np.empty(len(mesh.loops), dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", loop_vertex)
    starts = np.empty(len(mesh.polygons), dtype=np.int64)
    mesh.polygons.foreach_get("loop_start", starts)
    # a mesh's own UVs, matched corner by corner
    if geom.texcoords is not None and geom.texture_type == "2d" and len(made) == len(starts):
        faces, uvs = geom.faces[made], geom.texcoords[made]  # type: ignore[index]
        corner = np.argmax(faces[np.repeat(np.arange(len(made)), 3)] == loop_vertex[:, None], axis=1)
        uv = uvs[np.repeat(np.arange(len(made)), 3), corner]
    elif geom.texture_type == "cube":
        assert geom.texture is not None
        h, w = geom.texture.shape[:2]
        uv = cube_uv(points * np.array(geom.texscale), starts, loop_vertex, faces=6 if h == 6 * w else 1, texels=w)
    else:
        uv = planar_uv(points, geom.texscale[:2])[loop_vertex]
    layer = mesh.uv_layers.new(name="UVMap")
    layer.data.foreach_set("uv", uv.astype(np.float32).reshape(-1))


def _geom_object(
    geom: GeomShape, *, base_dir: Any, source: Any, images: dict[int, Any], split_caps: bool, material: Material
) -> Any:
    """The geom's mesh object and material. `split_caps`: a cylinder's (or capsule's) side is smoothed apart from its flat
    ends, its normals straight out as MuJoCo's (smoothed with them, the side's normals tilt up to 45 degrees toward the
    ends; kept so in physics.look 'physical', whose frames a shipped agent was trained on)."""
    mesh = bpy.data.meshes.new(geom.name)
    bm = bmesh.new()
    points, made = _shape(bm, geom, split_caps)
    for face in bm.faces:
        face.smooth = geom.kind in ("sphere", "ellipsoid", "capsule", "cylinder")
    # made by create_uvsphere (a mesh keeps MuJoCo's face order: _uv_map reads it)
    if geom.kind in (
        "sphere",
        "ellipsoid",
        "capsule",
    ):
        sort_faces(bm)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(geom.name, mesh)
    material = replace(material, color=tuple(float(v) for v in geom.rgba), roughness=0.6)
    mat = make_material(
        f"mjcf-{geom.name}", material, base_dir=base_dir, source=source, path=("physics", "model"), track=lambda d: d
    )
    if geom.material:
        mat[MUJOCO_MATERIAL] = geom.material
    if geom.texture is not None:  # MuJoCo multiplies the texture by the geom's colour
        _uv_map(mesh, geom, points, made)
        tint_image(mat, _texture_image(geom, images), repeat=geom.texture_type == "2d")
    mesh.materials.append(mat)
    obj.rotation_mode = "QUATERNION"
    obj.location = geom.pos
    obj.rotation_quaternion = Quaternion(geom.quat)
    return obj
