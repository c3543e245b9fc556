"""A :class:`~visualenv.render.distractions.Distraction` drawn in a Blender scene: cameras moved, colours shifted, the
sky's shift and the background drawn on a backdrop.

Each observation camera gets a child camera (the same lens, parented to it) whose local pose is the orbit about the
point the camera looks at (:func:`~visualenv.render.distractions.orbit`, the suite's sphere about it): the parent goes
on following its bindings or its MuJoCo body, the child follows it, and the observation is rendered through the child.
A MuJoCo model's floor (its material 'grid') takes the distraction's floor alpha (:func:`fade_floor`). Colours shift where colour bindings write (each Principled
material's base colour or its tint, :func:`~visualenv.render.blender.look.materials.color_sockets`), so a MuJoCo look and
a bound colour are shifted alike. A value is written only when it changes: Cycles updates a shader on every write.

The sky's shift and the background are drawn on a *backdrop* (:func:`make_backdrops`): a sphere about the camera
just inside its far clip, seen by camera rays only, which lets 1 - opacity of the sky through and adds
(1 - opacity) x the sky's shift + opacity x the background's pattern. It lights nothing, and the world is left as it
was, so the scene is lit as without distractions to the bit (the world's own camera-only branch did not: Goalie's
field came out 4 levels brighter with a background, its world's light sampled otherwise). Its numbers are attributes
of its instance, so a batch draws one backdrop per env, each with its own (:mod:`batch_distractions`), and a tile
equals its env alone. Its cost: every camera ray meets one more surface (docs/distractions.md).
"""

from __future__ import annotations

import re
from typing import Any, Callable, Sequence

import bmesh
import bpy
import numpy as np
from mathutils import Matrix, Vector

from visualenv.render.blender.batch.env_attributes import env_attribute
from visualenv.render.blender.batch.instance_nodes import geometry_node_group
from visualenv.render.blender.look.materials import MUJOCO_MATERIAL, SHIFTED, color_sockets, ensure_node_tree
from visualenv.render.blender.look.video_backdrop import VIDEO, VideoAtlas, cube_lookup
from visualenv.render.distractions import Distraction, background, color_shifts, world_up
from visualenv.render.distractions import orbit as orbit_matrix

#: the orbit's centre when a camera's view axis hits nothing: this far along it
FALLBACK_FOCUS = 3.0
#: the MuJoCo material of a model's floor, whose alpha the suite sets (ground_plane_alpha)
FLOOR = "grid"
#: what Blender appends to a datablock's name that another holds
TAKEN_SUFFIX = re.compile(r"\.\d{3,}$")
#: the custom property that marks a backdrop (a ray cast for the orbit's centre that meets it met nothing)
BACKDROP = "visualenv_backdrop"
#: the backdrop's attributes, three numbers each: the sky's shift, the background's two colours, and its pattern's
#: scale, time (its fourth coordinate) and opacity
SKY_SHIFT, FIRST, SECOND, PATTERN = (
    "visualenv_sky_shift",
    "visualenv_background_first",
    "visualenv_background_second",
    "visualenv_background_pattern",
)
#: the backdrop's vertices lie this share of the camera's far clip away, its faces at least 99.89 % of that (an
#: icosphere of BACKDROP_SUBDIVISIONS, 5,120 faces): what lies in the last 0.2 % before the far clip is seen through it
BACKDROP_REACH, BACKDROP_SUBDIVISIONS = 0.999, 5
#: ray visibilities a backdrop turns off: only camera rays see it
UNSEEN_BY = ("visible_diffuse", "visible_glossy", "visible_transmission", "visible_volume_scatter", "visible_shadow")


class DistractionRig:
    """The cameras, colour sockets and backdrop of one env's scene that distractions change; :meth:`apply` draws one."""

    def __init__(
        self,
        scene: Any,
        cameras: list[Any],
        backdrop: bool = False,
        floor_alpha: float = 1.0,
        videos: bool = False,
        raw_colors: bool = False,
        own: Callable[[Any], object] = lambda image: None,
    ) -> None:
        """`backdrop`: make the backdrop, for the sky's shift and the background (a distraction with either will come);
        `floor_alpha`: the floor's opacity (:func:`fade_floor`); `videos`: the background is the suite's videos, in a
        scene whose colours are written `raw_colors` (:class:`VideoAtlas`, which gives `own` every image it makes)."""
        self._scene = scene
        #: whether the floor was made see-through (its rays then need transparent bounces)
        self.floor_faded = fade_floor(scene, floor_alpha)
        #: the observation camera each child stands for, by the parent's name
        self.children: dict[str, Any] = {}
        for camera in cameras:
            if camera.name in self.children:
                continue
            child = bpy.data.objects.new(f"{camera.name} distracted", camera.data)
            scene.collection.objects.link(child)
            child.parent = camera
            child.matrix_parent_inverse = Matrix.Identity(4)
            self.children[camera.name] = child
        self._focus: dict[str, tuple[float, np.ndarray]] = {}
        self._sockets = [sockets[0] for material in distracted_materials(scene) if (sockets := color_sockets(material))]
        self._base: list[tuple[float, ...]] = [tuple(socket.default_value) for socket in self._sockets]
        self._written = list(self._base)
        self._last: Distraction | None = None
        self._shifts = np.zeros((len(self._sockets) + 1, 3))  # the current distraction's (color_shifts), the sky's last
        #: the object that holds the backdrop, about the first camera (None: no background or colours)
        self.backdrop = None
        self._atlas = None
        if backdrop:
            first = next(iter(self.children.values()))
            self._atlas = VideoAtlas(f"{first.name} videos", 1, scene, raw_colors, own) if videos else None
            self.backdrop = make_backdrops(
                scene.collection, f"{first.name} backdrop", np.zeros((1, 3)), first.data.clip_end, self._atlas
            )
            self.backdrop.parent = first
            self.backdrop.matrix_parent_inverse = Matrix.Identity(4)

    def apply(self, distraction: Distraction) -> None:
        """Pose the child cameras, write the backdrop's numbers and the shifted colours: where a binding rewrote a colour
        since, from its new value. A render with the same distraction and no colour rewritten writes nothing."""
        changed = distraction != self._last
        if changed:
            for name, child in self.children.items():
                child.matrix_basis = orbit(distraction, *self._focus_of(name))
            self._shifts = color_shifts(distraction, len(self._sockets))
            if self.backdrop is not None:
                write_backdrops(self.backdrop, [distraction], self._shifts[-1:], self._atlas)
            self._last = distraction
        for i, socket in enumerate(self._sockets):
            now = tuple(socket.default_value)
            rewritten = now != self._written[i]  # a colour binding wrote it: shift its new value
            if not (changed or rewritten):
                continue
            if rewritten:
                self._base[i] = now
            value = self._shifted(i)
            if value != now:  # a write is a shader update in Cycles: only a change
                socket.default_value = value
            self._written[i] = tuple(socket.default_value)

    def _shifted(self, i: int) -> tuple[float, ...]:
        """Socket i's value under the current shifts, as the socket holds it (float32): an equal value is not written again."""
        base = self._base[i]
        value = (*np.clip(np.array(base[:3]) + self._shifts[i], 0.0, 1.0).tolist(), *base[3:])
        return tuple(np.asarray(value, dtype=np.float32).tolist())

    def _focus_of(self, name: str) -> tuple[float, np.ndarray]:
        """How far ahead of the camera its orbit's centre lies (:func:`focus_distance`) and the world's up in its frame,
        measured once."""
        if name not in self._focus:
            camera = self.children[name].parent
            self._scene.view_layers[0].update()
            pose = camera.matrix_world
            self._focus[name] = (
                focus_distance(self._scene, pose, camera.data.clip_start),
                world_up(np.array(pose, dtype=np.float64)),
            )
        return self._focus[name]


def distracted_materials(scene: Any) -> list[Any]:
    """Every Principled material of the scene's objects (one a colour binding writes), in the order their shifts are
    drawn (:func:`~visualenv.render.distractions.color_shifts`): by name without the ``.001`` Blender adds to a name
    taken (a second env in the process has them), so each env of a spec shifts its materials alike."""
    materials = {
        slot.material.name: slot.material
        for obj in scene.objects
        for slot in obj.material_slots
        if slot.material is not None and slot.material.node_tree is not None
    }
    ordered = [materials[name] for name in sorted(materials, key=lambda taken: TAKEN_SUFFIX.sub("", taken))]
    return [material for material in ordered if color_sockets(material) is not None]


def focus_distance(
    scene: Any,
    pose: Matrix,
    clip_start: float,
    offset: Vector | None = None,
    before_cast: Callable[[], object] = lambda: None,
) -> float:
    """How far ahead of a camera at `pose` (in its env's own frame; `offset`: where that frame stands in the scene) its
    orbit's centre lies: the point of its view axis nearest the env's origin (where a model stands, or the body a
    tracking camera keeps in view), else the first surface along the axis (`before_cast` readies the scene for the
    ray cast), else :data:`FALLBACK_FOCUS`."""
    origin, forward = pose.translation, (pose.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
    nearest = float(-origin.dot(forward))
    if nearest > clip_start:
        return nearest
    before_cast()
    camera = origin + offset if offset is not None else origin
    hit, where, _, _, obj, _ = scene.ray_cast(scene.view_layers[0].depsgraph, camera + forward * clip_start, forward)
    return float((where - camera).length) if hit and not obj.get(BACKDROP) else FALLBACK_FOCUS


def orbit(distraction: Distraction, focus: float, up: np.ndarray) -> Matrix:
    """The camera's local pose on the suite's sphere about the point `focus` ahead of it (`up`: the world's up in its
    frame): :func:`visualenv.render.distractions.orbit` as a Blender matrix."""
    return Matrix(orbit_matrix(distraction, focus, up).tolist())


def fade_floor(scene: Any, alpha: float) -> bool:
    """Every material of a MuJoCo model's floor (made of its material :data:`FLOOR`) at opacity `alpha`, as the suite
    sets that material's alpha: the rest of each camera ray goes on to what lies behind (the sky, the backdrop).
    Whether any was faded (an `alpha` of 1 changes nothing)."""
    if alpha >= 1.0:
        return False
    floors = {
        slot.material.name: slot.material
        for obj in scene.objects
        for slot in obj.material_slots
        if slot.material is not None and slot.material.get(MUJOCO_MATERIAL) == FLOOR and slot.material.node_tree
    }
    faded = False
    for material in floors.values():
        bsdf = next((n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
        if bsdf is not None:
            bsdf.inputs["Alpha"].default_value = alpha
            faded = True
    return faded


def shift_by_attribute(material: Any, name: str) -> None:
    """The material's colour (where a binding writes) plus the attribute `name` (an instance's, else its object's custom
    property), kept in [0, 1]: a batch's per-env shift. The binding then writes the shift node's second colour."""
    sockets = color_sockets(material)
    assert sockets is not None, "a distracted material has a Principled BSDF (distracted_materials)"
    target = sockets[0]
    nodes, links = material.node_tree.nodes, material.node_tree.links
    shift = mix_node(nodes, "ADD")
    shift.name = SHIFTED
    shift.clamp_result = True
    shifted, base = [sock for sock in shift.inputs if sock.type == "RGBA"]
    links.new(env_attribute(nodes, name).outputs["Color"], shifted)
    if target.is_linked:  # a node drives the colour
        links.new(target.links[0].from_socket, base)
    else:
        base.default_value = target.default_value
    links.new(next(sock for sock in shift.outputs if sock.type == "RGBA"), target)


def mix_node(nodes: Any, blend: str) -> Any:
    """A Mix node of two colours by `blend` (its blend type), its factor 1."""
    node = nodes.new("ShaderNodeMix")
    node.data_type = "RGBA"
    node.blend_type = blend
    node.inputs["Factor"].default_value = 1.0
    return node


def make_backdrops(
    collection: Any, name: str, places: np.ndarray, clip_end: float, atlas: VideoAtlas | None = None
) -> Any:
    """Backdrops in `collection` about `places` (``(n, 3)``, in the space of the object returned: parent it to a camera)
    for cameras whose far clip is `clip_end`: instances of one hidden icosphere just inside it on the points of a mesh,
    whose attributes hold each one's numbers (:func:`write_backdrops`). `atlas`: the suite's videos, a tile per point."""
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    try:
        bmesh.ops.create_icosphere(bm, subdivisions=BACKDROP_SUBDIVISIONS, radius=clip_end * BACKDROP_REACH)
        bm.to_mesh(mesh)
    finally:
        bm.free()
    mesh.materials.append(backdrop_material(name, atlas))
    sphere = bpy.data.objects.new(name, mesh)
    collection.objects.link(sphere)
    for visibility in UNSEEN_BY:
        setattr(sphere, visibility, False)
    sphere.hide_render = True  # its instances draw it
    points = bpy.data.meshes.new(f"{name} places")
    points.vertices.add(len(places))
    points.vertices.foreach_set("co", np.asarray(places, dtype=np.float32).ravel())
    for key in (SKY_SHIFT, FIRST, SECOND, PATTERN, VIDEO):
        points.attributes.new(key, "FLOAT_COLOR", "POINT")
    holder = bpy.data.objects.new(f"{name} places", points)
    collection.objects.link(holder)
    holder.modifiers.new("visualenv backdrops", "NODES").node_group = _instancing(name, sphere)
    sphere[BACKDROP] = holder[BACKDROP] = True
    return holder


def write_backdrops(
    holder: Any, distractions: Sequence[Distraction], sky_shifts: np.ndarray, atlas: VideoAtlas | None = None
) -> None:
    """Each backdrop's numbers (one distraction per point of `holder`, made by :func:`make_backdrops`; its sky's shift
    given, ``(n, 3)``: the last row of its colour shifts): the shift, the background's colours, and its pattern's
    scale, time and opacity (0: no background); with the suite's videos, each one's frame in `atlas`, wholly opaque."""
    videos = [atlas is not None and d.video >= 0 for d in distractions]
    shown = [None if video else background(d) for d, video in zip(distractions, videos)]
    tiles = atlas.tiles() if atlas is not None else np.zeros((len(distractions), 2))
    if atlas is not None:
        atlas.show([d.video_frame for d in distractions])
    numbers = {
        SKY_SHIFT: np.asarray(sky_shifts),
        FIRST: np.array([b.first if b else (0.0, 0.0, 0.0) for b in shown]),
        SECOND: np.array([b.second if b else (0.0, 0.0, 0.0) for b in shown]),
        PATTERN: np.array(
            [
                (1.0, 0.0, 1.0) if video else (b.scale, b.time, b.opacity) if b else (1.0, 0.0, 0.0)
                for b, video in zip(shown, videos)
            ]
        ),
        VIDEO: np.column_stack([tiles, np.array(videos, dtype=np.float64)]),
    }
    for key, values in numbers.items():
        rgba = np.ones((len(values), 4), dtype=np.float32)
        rgba[:, :3] = values
        holder.data.attributes[key].data.foreach_set("color", rgba.ravel())
    holder.data.update_tag()


def _instancing(name: str, obj: Any) -> Any:
    """Geometry Nodes: an instance of `obj` on every point (the points' attributes go with it)."""
    group = geometry_node_group(name)
    nodes, links = group.nodes, group.links
    info = nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "ORIGINAL"
    info.inputs["Object"].default_value = obj
    info.inputs["As Instance"].default_value = True
    on_points = nodes.new("GeometryNodeInstanceOnPoints")
    links.new(nodes.new("NodeGroupInput").outputs[0], on_points.inputs["Points"])
    links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    links.new(on_points.outputs["Instances"], nodes.new("NodeGroupOutput").inputs[0])
    return group


def backdrop_material(name: str, atlas: VideoAtlas | None = None) -> Any:
    """The backdrop's shader: Transparent of 1 - opacity, plus Emission of (1 - opacity) x the sky's shift + opacity x
    the pattern, two colours blended by a 4D noise of the ray's direction (scale and time its attributes'), as one
    env's world shows them to its camera rays; every number an attribute. With `atlas`, the pattern gives way to the
    env's video frame where its attribute says so (:func:`cube_lookup`). Not a light Cycles samples."""
    material = bpy.data.materials.new(name)
    ensure_node_tree(material)
    material.cycles.emission_sampling = "NONE"
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    pattern = nodes.new("ShaderNodeSeparateXYZ")
    links.new(env_attribute(nodes, PATTERN).outputs["Vector"], pattern.inputs[0])
    direction = nodes.new("ShaderNodeVectorMath")
    direction.operation = "SCALE"
    direction.inputs["Scale"].default_value = -1.0
    links.new(nodes.new("ShaderNodeNewGeometry").outputs["Incoming"], direction.inputs[0])
    noise = nodes.new("ShaderNodeTexNoise")
    noise.noise_dimensions = "4D"
    links.new(direction.outputs["Vector"], noise.inputs["Vector"])
    links.new(pattern.outputs["X"], noise.inputs["Scale"])
    links.new(pattern.outputs["Y"], noise.inputs["W"])
    blend, glow = mix_node(nodes, "MIX"), mix_node(nodes, "MIX")
    links.new(noise.outputs["Fac"], blend.inputs["Factor"])
    shown = blend  # the pattern, or the video's frame
    if atlas is not None:
        video = env_attribute(nodes, VIDEO)
        on = nodes.new("ShaderNodeSeparateXYZ")
        links.new(video.outputs["Vector"], on.inputs[0])
        frame = cube_lookup(nodes, links, direction.outputs["Vector"], video.outputs["Vector"], atlas)
        shown = mix_node(nodes, "MIX")
        links.new(on.outputs["Z"], shown.inputs["Factor"])
        a, b = [sock for sock in shown.inputs if sock.type == "RGBA"]
        links.new(next(sock for sock in blend.outputs if sock.type == "RGBA"), a)
        links.new(frame.outputs["Color"], b)
    for node, first, second in (
        (blend, env_attribute(nodes, FIRST), env_attribute(nodes, SECOND)),
        (glow, env_attribute(nodes, SKY_SHIFT), shown),
    ):
        a, b = [sock for sock in node.inputs if sock.type == "RGBA"]
        links.new(first.outputs["Color"], a)
        links.new(next(sock for sock in second.outputs if sock.type == "RGBA"), b)
    links.new(pattern.outputs["Z"], glow.inputs["Factor"])
    through = nodes.new("ShaderNodeMath")
    through.operation = "SUBTRACT"
    through.inputs[0].default_value = 1.0
    links.new(pattern.outputs["Z"], through.inputs[1])
    transparent, emission = nodes.new("ShaderNodeBsdfTransparent"), nodes.new("ShaderNodeEmission")
    both = nodes.new("ShaderNodeAddShader")
    links.new(through.outputs["Value"], transparent.inputs["Color"])
    links.new(next(sock for sock in glow.outputs if sock.type == "RGBA"), emission.inputs["Color"])
    emission.inputs["Strength"].default_value = 1.0
    links.new(transparent.outputs[0], both.inputs[0])
    links.new(emission.outputs[0], both.inputs[1])
    links.new(both.outputs[0], nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    return material
