"""Each env's own distraction in one batch render: :class:`BatchDistractions`.

Env k of a batch draws what env k alone draws (docs/distractions.md), by the batch's own means:

* **camera**: env k's observation camera orbits as the env's own child camera does
  (:func:`~visualenv.render.blender.distractions.orbit` about the point measured at env k's first render), and the batch
  follows it as it follows a camera that moves and turns (:mod:`batched`): env k's copy is moved so that its orbited
  camera stands where the tiles camera looks from, and env k's rays are turned by its orbited rotation. A change of any
  env's orbit makes Cycles compile the tiles shader again, as for a camera the state turns;
* **colours**: every material adds an attribute to its colour (:func:`~visualenv.render.blender.distractions.shift_by_attribute`,
  an Attribute node of type Instancer): each env's shifts are attributes of its instances
  (:meth:`~visualenv.render.blender.instances.InstancedCopies.write_env_attributes`) and custom properties of its copied
  objects. So no static mesh is realized into one mesh of every env (its envs would read one shift);
* **sky and background**: one backdrop per env, instances of one sphere about each env's ray origin, each with its own
  numbers as attributes (:func:`~visualenv.render.blender.distractions.backdrop_material`). The copies stand twice the
  cameras' far clip apart, so that no env's backdrop reaches into another's.

Numbers are written when an env's distraction changes: at its resets, and every step when dynamic.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import bpy
import numpy as np

from visualenv.render.blender.distractions import (FIRST, PATTERN, SECOND, SKY_SHIFT, backdrop_material, backdrop_values,
                                                   distracted_materials, make_backdrop, orbit, shift_by_attribute)
from visualenv.render.blender.env_attributes import EnvAttributes, shift_name
from visualenv.render.distractions import Distraction, color_shifts
from visualenv.spec.models import Distractions


class BatchDistractions:
    """The distractions of a batch's envs (:attr:`current`, one per env), drawn into its scene by :meth:`draw`."""

    def __init__(self, settings: Distractions, scene: Any, num_envs: int) -> None:
        """Made with the scene as one env's (its materials in the order one env draws their shifts), before the copies."""
        on = settings.difficulty > 0
        #: whether the observation cameras orbit: each env's copy then follows its camera and its rays turn
        self.orbiting = on and settings.camera
        #: whether the materials read each env's shifts, and whether each env has a backdrop
        self.shifting = on and settings.colors
        self.backdropped = on and (settings.colors or settings.background)
        materials = distracted_materials(scene)
        self._count = len(materials)
        if self.shifting:
            for i, material in enumerate(materials):
                shift_by_attribute(material, shift_name(i))
        #: each env's distraction, as its env handed it (:meth:`BatchedBlenderRenderer.distract_batch`)
        self.current = [Distraction()] * num_envs
        self._drawn: list[Distraction | None] = [None] * num_envs
        self._values: EnvAttributes | None = None  # where each env's shifts go
        self._backdrop: Any = None  # the mesh of the backdrops' points
        self._focus: dict[tuple[int, int], float] = {}  # (camera, env) -> its orbit's centre
        self._orbits: dict[tuple[int, int], tuple[Distraction, np.ndarray]] = {}  # (camera, env) -> the orbit drawn

    def attach(self, values: EnvAttributes) -> None:
        """The batch's copied objects and instances, which take each env's shifts."""
        self._values = values

    def make_backdrops(self, collection: Any, places: np.ndarray, clip_end: float) -> Any:
        """Each env's backdrop about its place (``(N, 3)``: where its rays start): instances of one hidden sphere on the
        points of a mesh, whose attributes are each env's numbers. Returns the object that holds them."""
        name = f"{collection.name} backdrop"
        sphere = make_backdrop(collection, name, clip_end, backdrop_material(name))
        sphere.hide_render = True  # its instances draw it
        mesh = bpy.data.meshes.new(f"{name} places")
        mesh.vertices.add(len(places))
        mesh.vertices.foreach_set("co", np.asarray(places, dtype=np.float32).ravel())
        for key in (SKY_SHIFT, FIRST, SECOND, PATTERN):
            mesh.attributes.new(key, "FLOAT_COLOR", "POINT")
        holder = bpy.data.objects.new(f"{name} places", mesh)
        collection.objects.link(holder)
        holder.modifiers.new("visualenv backdrops", "NODES").node_group = _instancing(name, sphere)
        self._backdrop = mesh
        return holder

    def draw(self) -> None:
        """Write the numbers of every env whose distraction changed since the last draw."""
        changed = [k for k, (now, drawn) in enumerate(zip(self.current, self._drawn)) if now != drawn]
        if not changed:
            return
        shifts = np.stack([color_shifts(d, self._count) for d in self.current])  # (N, materials + 1, 3), the sky's last
        if self.shifting and self._values is not None:
            self._values.write({shift_name(i): shifts[:, i] for i in range(self._count)})
        if self._backdrop is not None:
            values = [backdrop_values(d, shifts[k, -1]) for k, d in enumerate(self.current)]
            for key in (SKY_SHIFT, FIRST, SECOND, PATTERN):
                self._backdrop.attributes[key].data.foreach_set("color", _colors(np.array([v[key] for v in values])).ravel())
            self._backdrop.update_tag()
        self._drawn = list(self.current)

    def orbited(self, camera: int, poses: Sequence[np.ndarray], measure: Callable[[int], float]) -> list[np.ndarray]:
        """Each env's camera pose (``(4, 4)`` in its own copy) orbited by its distraction about its centre, measured once
        per env by `measure` (:func:`~visualenv.render.blender.distractions.focus_distance`) for this `camera` (a pointer)."""
        out = []
        for k, (pose, distraction) in enumerate(zip(poses, self.current)):
            key = (camera, k)
            if key not in self._focus:
                self._focus[key] = measure(k)
            drawn = self._orbits.get(key)
            if drawn is None or drawn[0] != distraction:
                drawn = (distraction, np.array(orbit(distraction, self._focus[key]), dtype=np.float64))
                self._orbits[key] = drawn
            out.append(pose @ drawn[1])
        return out


def _colors(rgb: np.ndarray) -> np.ndarray:
    """``(N, 3)`` numbers as a FLOAT_COLOR attribute's ``(N, 4)`` float32 values (alpha 1)."""
    out = np.ones((len(rgb), 4), dtype=np.float32)
    out[:, :3] = rgb
    return out


def _instancing(name: str, obj: Any) -> Any:
    """Geometry Nodes: an instance of `obj` on every point (its attributes go with it)."""
    group = bpy.data.node_groups.new(name, "GeometryNodeTree")
    group.interface.new_socket(name="Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket(name="Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
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
