"""A :class:`~visualenv.render.distractions.Distraction` drawn in a Blender scene: cameras moved, colours shifted.

Each observation camera gets a child camera (the same lens, parented to it) whose local pose is the orbit about the
point the camera looks at: the parent goes on following its bindings or its MuJoCo body, the child follows it, and
the observation is rendered through the child. Colours shift where colour bindings write (each Principled
material's base colour or its tint, :func:`~visualenv.render.blender.materials.color_sockets`), so a MuJoCo look and
a bound colour are shifted alike; the sky shifts as the model's skybox, the image sky's tint or the world's colour. A value is
written only when it changes: Cycles updates a shader on every write.
"""

from __future__ import annotations

import re
from typing import Any

import bpy
import numpy as np
from mathutils import Matrix, Vector

from visualenv.render.blender.materials import SKY_MAP_RESOLUTION, SKY_TINT, SKYBOX, color_sockets
from visualenv.render.distractions import Distraction, background, color_shifts

#: the name of the Mix node that adds the sky's shift behind a model's skybox
SKY_SHIFT = "visualenv distraction sky"
#: the orbit's centre when a camera's view axis hits nothing: this far along it
FALLBACK_FOCUS = 3.0
#: what Blender appends to a datablock's name that another holds
TAKEN_SUFFIX = re.compile(r"\.\d{3,}$")


class DistractionRig:
    """The cameras and colour sockets of one scene that distractions move; :meth:`apply` draws one distraction."""

    def __init__(self, scene: Any, cameras: list[Any], backdrop: bool = False) -> None:
        """`backdrop`: build the background's nodes (a distraction with a background will come)."""
        self._scene = scene
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
        self._focus: dict[str, float] = {}
        self._sockets = self._color_sockets(scene)
        #: a skybox's socket holds its shift s as (s + 1) / 2 (a Linear Light mix adds 2b - 1), not a colour
        self._offset = len(self._sockets) - 1 if self._sockets and self._sockets[-1].node.name == SKY_SHIFT else None
        self._base = [tuple(socket.default_value) for socket in self._sockets]
        self._written = list(self._base)
        self._last: Distraction | None = None
        self._shifts = np.zeros((len(self._sockets), 3))  # the current distraction's (color_shifts)
        self._backdrop = _backdrop_sockets(scene.world) if backdrop else None

    @staticmethod
    def _color_sockets(scene: Any) -> list[Any]:
        """Every Principled material's colour socket in the scene (where a colour binding writes), then the sky's. By name without the ``.001`` Blender
        adds to a name taken (a second env in the process has them): each env of a spec shifts its materials alike."""
        materials = {slot.material.name: slot.material for obj in scene.objects for slot in obj.material_slots
                     if slot.material is not None and slot.material.node_tree is not None}
        sockets = []
        for name in sorted(materials, key=lambda taken: TAKEN_SUFFIX.sub("", taken)):
            found = color_sockets(materials[name])  # the socket a colour binding writes: both see one colour
            if found is not None:
                sockets.append(found[0])
        sky = _sky_socket(scene.world)
        return [*sockets, sky] if sky is not None else sockets

    def apply(self, distraction: Distraction) -> None:
        """Pose the child cameras and write the shifted colours: where a binding rewrote a colour since, from its new
        value. A render with the same distraction and no colour rewritten writes nothing."""
        changed = distraction != self._last
        if changed:
            for name, child in self.children.items():
                child.matrix_basis = orbit(distraction, self._focus_of(name))
            if self._backdrop is not None:
                _show_background(self._backdrop, distraction)
            self._shifts = color_shifts(distraction, len(self._sockets) - 1)
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
        base, shift = self._base[i], self._shifts[i]
        if i == self._offset:
            value = (*((shift + 1.0) / 2.0).tolist(), 1.0)
        else:
            value = (*np.clip(np.array(base[:3]) + shift, 0.0, 1.0).tolist(), *base[3:])
        return tuple(np.asarray(value, dtype=np.float32).tolist())

    def _focus_of(self, name: str) -> float:
        """How far ahead of the camera its orbit's centre lies, measured once: the point of its view axis nearest the
        world's origin (where a model stands, or the body a tracking camera keeps in view at reset), else the first
        surface along the axis, else :data:`FALLBACK_FOCUS`."""
        if name not in self._focus:
            camera = self.children[name].parent
            self._scene.view_layers[0].update()
            pose = camera.matrix_world
            origin, forward = pose.translation, (pose.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
            nearest = float(-origin.dot(forward))
            if nearest > camera.data.clip_start:
                self._focus[name] = nearest
            else:
                hit, where, *_ = self._scene.ray_cast(self._scene.view_layers[0].depsgraph, origin + forward * camera.data.clip_start, forward)
                self._focus[name] = float((where - origin).length) if hit else FALLBACK_FOCUS
        return self._focus[name]


def orbit(distraction: Distraction, focus: float) -> Matrix:
    """The camera's local pose that orbits it by yaw (about its up axis) and pitch (about its right axis) about the
    point `focus` ahead of it, zooms its distance to that point and rolls it about its view axis."""
    ahead = Matrix.Translation((0.0, 0.0, -focus))
    turn = Matrix.Rotation(distraction.yaw, 4, "Y") @ Matrix.Rotation(distraction.pitch, 4, "X")
    back = Matrix.Translation((0.0, 0.0, focus * distraction.zoom))
    return ahead @ turn @ back @ Matrix.Rotation(distraction.roll, 4, "Z")


def _sky_socket(world: Any) -> Any:
    """The colour socket that shifts the sky: a Linear Light mix behind a model's skybox (made here), the image sky's
    tint, or the world's unlinked Background colour; None where the world has none of them."""
    if world is None or world.node_tree is None:
        return None
    nodes, links = world.node_tree.nodes, world.node_tree.links
    skybox = nodes.get(SKYBOX)
    if skybox is not None:
        shift = nodes.get(SKY_SHIFT)
        if shift is None:
            shift = nodes.new("ShaderNodeMix")
            shift.name, shift.data_type, shift.blend_type, shift.clamp_result = SKY_SHIFT, "RGBA", "LINEAR_LIGHT", True
            shift.inputs["Factor"].default_value = 1.0
            first, second = [sock for sock in shift.inputs if sock.type == "RGBA"]
            second.default_value = (0.5, 0.5, 0.5, 1.0)  # 2 x 0.5 - 1: no shift
            out = next(sock for sock in shift.outputs if sock.type == "RGBA")
            for link in list(skybox.outputs["Color"].links):
                links.new(out, link.to_socket)
            links.new(skybox.outputs["Color"], first)
        return [sock for sock in shift.inputs if sock.type == "RGBA"][1]
    tint = nodes.get(SKY_TINT)
    if tint is not None:
        return [sock for sock in tint.inputs if sock.type == "RGBA"][1]
    background = next((n for n in nodes if n.type == "BACKGROUND"), None)
    return background.inputs["Color"] if background is not None and not background.inputs["Color"].is_linked else None


def _backdrop_sockets(world: Any) -> dict[str, Any] | None:
    """The world's output wrapped so that camera rays see a noise pattern of two colours where `on` is 1 (the rest of
    the world, what lights the scene, as it was); the sockets :func:`_show_background` writes. None without a world."""
    if world is None or world.node_tree is None:
        return None
    nodes, links = world.node_tree.nodes, world.node_tree.links
    out = next((n for n in nodes if n.type == "OUTPUT_WORLD"), None)
    if out is None or not out.inputs["Surface"].is_linked:
        return None
    original = out.inputs["Surface"].links[0].from_socket
    coords, noise = nodes.new("ShaderNodeTexCoord"), nodes.new("ShaderNodeTexNoise")
    noise.noise_dimensions = "4D"
    links.new(coords.outputs["Generated"], noise.inputs["Vector"])
    blend = nodes.new("ShaderNodeMix")
    blend.data_type = "RGBA"
    links.new(noise.outputs["Fac"], blend.inputs["Factor"])
    first, second = [sock for sock in blend.inputs if sock.type == "RGBA"]
    shown = nodes.new("ShaderNodeBackground")
    links.new(next(sock for sock in blend.outputs if sock.type == "RGBA"), shown.inputs["Color"])
    path, on = nodes.new("ShaderNodeLightPath"), nodes.new("ShaderNodeMath")
    on.operation = "MULTIPLY"
    links.new(path.outputs["Is Camera Ray"], on.inputs[0])
    mix = nodes.new("ShaderNodeMixShader")
    links.new(on.outputs["Value"], mix.inputs["Fac"])
    links.new(original, mix.inputs[1])
    links.new(shown.outputs["Background"], mix.inputs[2])
    links.new(mix.outputs["Shader"], out.inputs["Surface"])
    if world.cycles.sampling_method == "AUTOMATIC":  # a textured world's automatic map costs seconds at every change
        world.cycles.sampling_method = "MANUAL"
        world.cycles.sample_map_resolution = SKY_MAP_RESOLUTION
    return {"first": first, "second": second, "scale": noise.inputs["Scale"], "time": noise.inputs["W"], "on": on.inputs[1]}


def _show_background(sockets: dict[str, Any], distraction: Distraction) -> None:
    """Write the distraction's background (or none) into the world's sockets."""
    shown = background(distraction)
    sockets["on"].default_value = 0.0 if shown is None else shown.opacity
    if shown is not None:
        sockets["first"].default_value = (*shown.first, 1.0)
        sockets["second"].default_value = (*shown.second, 1.0)
        sockets["scale"].default_value = shown.scale
        sockets["time"].default_value = shown.time
