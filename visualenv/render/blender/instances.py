"""A batch's meshes as Geometry Nodes instances, their poses written from numpy: :class:`InstancedCopies`.

Moving N linked duplicates costs Blender a Python write, a depsgraph evaluation
and a Cycles sync per object: about 60 ms a step for VisualCartPole's 2,048
moving objects at N = 1,024. And every object in the scene, moving or not, adds
to Blender's update of a moved one (2,048 static objects: about 20 ms). Here
each mesh is one *instancer*: a mesh of N points (one per env) whose Geometry
Nodes modifier puts an instance of the original mesh on every point and gives
it the point's 4x4 transform attribute as its world matrix. A step computes
every env's world matrices in numpy from the binding values (location, Euler
XYZ rotation, scale, down the chain of parents, then the env's grid place) and
writes each attribute with one ``foreach_set``: no Python per env or per
copied object. Static meshes (the floor) are instanced too, posed once.

An env's visibility is its point's selection (a hidden instance is left out),
and a bound colour an instance attribute that the mesh's own materials read
with an Attribute node (type Instancer). The instances stay instances:
realizing them, or merging the meshes, makes Cycles rebuild the geometry every
step (about four times the cost); Cycles' persistent data keeps them.

What numpy cannot compute so stays a copy (:func:`removable`): lights (a light's
strength and colour are its own data, not an instance attribute), moving
cameras, objects with constraints, animation, deltas, non-XYZ rotation modes or
non-object parents, aimed objects, objects whose texture is bound, and the
parents of any copied object (the copy needs its parent).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import bpy
import numpy as np

from visualenv.render.base import BindingTarget
from visualenv.render.blender.materials import color_sockets

#: the bindable properties the instanced path computes; any other binding keeps its object a copy
COMPUTED = frozenset({"location", "rotation", "scale", "visible", "color"})
#: attribute names on the instancers' points (and so on their instances)
TRANSFORM, VISIBLE, COLOR = "visualenv_transform", "visualenv_visible", "visualenv_color"


def _computable(obj: Any, bound: dict[int, set[str]], aimed: set[int]) -> bool:
    """Whether numpy can compute this object's world matrix from its bindings, as Blender would (ancestors too)."""
    while obj is not None:
        if obj.type not in ("MESH", "EMPTY") or obj.constraints or obj.rotation_mode != "XYZ" or obj.parent_type != "OBJECT":
            return False
        animation = obj.animation_data
        if animation is not None and (animation.action is not None or len(animation.drivers) or len(animation.nla_tracks)):
            return False
        if any(obj.delta_location) or any(obj.delta_rotation_euler) or tuple(obj.delta_scale) != (1.0, 1.0, 1.0):
            return False
        if obj.as_pointer() in aimed or not bound.get(obj.as_pointer(), set()) <= COMPUTED:
            return False
        obj = obj.parent
    return True


def removable(copied: Sequence[Any], bindings: Iterable[BindingTarget], objects: dict[str, Any], aimed: Iterable[str]) -> set[int]:
    """Pointers of the objects that need no copies, with only such objects (or objects never copied) under them:
    meshes and empties whose world matrices numpy computes (:func:`_computable`; the meshes are drawn as instances,
    moving or not: every object in the scene adds to Blender's update of a moved one, about 10 us each), and cameras
    that nothing moves (a batch renders through its own tiles camera; a moving camera's copies place their anchors)."""
    bound: dict[int, set[str]] = {}
    for target in bindings:
        if target.object in objects:
            bound.setdefault(objects[target.object].as_pointer(), set()).add(target.property)
    aimed_ptrs = {objects[name].as_pointer() for name in aimed if name in objects}
    copied_ptrs = {o.as_pointer() for o in copied}

    def dynamic(obj: Any) -> bool:
        return any(o.as_pointer() in bound for o in _chain(obj))

    candidates = {o.as_pointer(): o for o in copied if _computable(o, bound, aimed_ptrs)
                  or (o.type == "CAMERA" and not dynamic(o) and o.as_pointer() not in aimed_ptrs)}
    changed = True
    while changed:  # drop any candidate with a copied object under it that is not removable
        changed = False
        for ptr, obj in list(candidates.items()):
            if any(c.as_pointer() in copied_ptrs and c.as_pointer() not in candidates for c in obj.children_recursive):
                del candidates[ptr]
                changed = True
    return set(candidates)


def _chain(obj: Any, anchor: Any = None) -> Iterable[Any]:
    """The object and its ancestors, up to (not including) `anchor`."""
    while obj is not None and obj != anchor:
        yield obj
        obj = obj.parent


@dataclass
class _Node:
    """One object whose world matrix is computed: its fixed parts and where its bindings' values sit."""

    obj: Any
    parent: int | None  # index of its parent's node; None: it hangs from its copy's anchor
    parent_inverse: np.ndarray
    location: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray
    slices: dict[str, slice] = field(default_factory=dict)  # property -> its values in the binding table
    static: bool = False  # no binding moves it or its ancestors: its world matrix is computed once
    world: np.ndarray | None = None  # a static node's world matrices (relative to its anchor)


@dataclass
class _Instancer:
    """One original mesh drawn once per env: its node, its point mesh and what its points carry."""

    node: int
    mesh: Any
    visible: list[slice]  # visible bindings that hide it: its own and its empty ancestors' (none: the original was hidden)
    selected: bool  # whether the points carry a visible attribute
    color: slice | None
    last: dict[str, np.ndarray] = field(default_factory=dict)


class InstancedCopies:
    """The batch's removable objects (:func:`removable`), drawn by one instancer per mesh; :meth:`write` poses every env."""

    def __init__(self, collection: Any, anchor: Any, originals: Sequence[Any], bindings: Sequence[BindingTarget],
                 objects: dict[str, Any], num_envs: int) -> None:
        self.num_envs = num_envs
        originals = [o for o in originals if o.type in ("MESH", "EMPTY")]  # the cameras removed need no instances
        names = {obj.as_pointer(): name for name, obj in objects.items()}
        starts: dict[tuple[str, str], slice] = {}
        start = 0
        for target in bindings:
            starts[(target.object, target.property)] = slice(start, start + target.size)
            start += target.size
        self.size = start
        order: list[Any] = []  # every removed object and its ancestors, parents first
        for obj in originals:
            for o in reversed(list(_chain(obj, anchor))):
                if o not in order:
                    order.append(o)
        index = {o.as_pointer(): i for i, o in enumerate(order)}
        self._nodes: list[_Node] = []
        for o in order:
            name = names.get(o.as_pointer(), "")
            slices = {prop: s for (n, prop), s in starts.items() if n == name and prop in COMPUTED}
            parent = index.get(o.parent.as_pointer()) if o.parent is not None else None
            static = not ({"location", "rotation", "scale"} & set(slices)) and (parent is None or self._nodes[parent].static)
            self._nodes.append(_Node(o, parent, _matrix(o.matrix_parent_inverse) if parent is not None else np.eye(4),
                                     np.array(o.location), np.array(o.rotation_euler), np.array(o.scale), slices, static))
        self._instancers: list[_Instancer] = []
        for obj in originals:
            if obj.type == "MESH":
                self._instancers.append(self._instancer(collection, obj, index[obj.as_pointer()], anchor))
        for obj in originals:
            obj.hide_render = True  # its instances draw it, env 0's among them

    def _instancer(self, collection: Any, obj: Any, node: int, anchor: Any) -> _Instancer:
        """A mesh of N points under a Geometry Nodes modifier that instances `obj` on each, posed by its transform attribute."""
        chain = list(_chain(obj, anchor))
        visible = [self._nodes[node].slices["visible"]] if "visible" in self._nodes[node].slices else []
        color = self._nodes[node].slices.get("color")
        for ancestor in chain[1:]:
            slices = self._nodes[self._node_of(ancestor)].slices
            if ancestor.type == "EMPTY" and "visible" in slices:
                visible.append(slices["visible"])  # an empty's visibility is that of everything under it
            if color is None and ancestor.type == "EMPTY" and "color" in slices:
                color = slices["color"]
        mesh = bpy.data.meshes.new(f"{obj.name}-instances")
        mesh.vertices.add(self.num_envs)
        mesh.attributes.new(TRANSFORM, "FLOAT4X4", "POINT")
        selected = bool(visible) or obj.hide_render  # a visible binding overrides how the original was set
        if selected:
            mesh.attributes.new(VISIBLE, "BOOLEAN", "POINT")
        if color is not None:
            mesh.attributes.new(COLOR, "FLOAT_COLOR", "POINT")
            for slot in obj.material_slots:
                if slot.material is not None:
                    _read_instance_color(slot.material)
        holder = bpy.data.objects.new(f"{obj.name}-instances", mesh)
        collection.objects.link(holder)
        modifier = holder.modifiers.new("visualenv instances", "NODES")
        modifier.node_group = _node_group(f"{obj.name}-instances", obj, selected)
        return _Instancer(node, mesh, visible, selected, color)

    def _node_of(self, obj: Any) -> int:
        return next(i for i, n in enumerate(self._nodes) if n.obj == obj)

    def write(self, values: np.ndarray, offsets: np.ndarray) -> None:
        """Pose every env's instances: `values` the binding table ``(N, size)``, `offsets` each env's anchor, a
        translation ``(N, 3)`` or a whole matrix ``(N, 4, 4)``.

        An attribute is written (and its mesh tagged for the depsgraph) only when it changed.
        """
        n = self.num_envs
        worlds: list[np.ndarray] = []
        for node in self._nodes:
            if node.world is not None:
                worlds.append(node.world)
                continue
            local = node.parent_inverse @ _basis(node, values, n)
            worlds.append(local if node.parent is None else worlds[node.parent] @ local)
            if node.static:
                node.world = worlds[-1]
        for inst in self._instancers:
            if offsets.ndim == 3:
                world = offsets @ worlds[inst.node]
            else:
                world = worlds[inst.node].copy()
                world[:, :3, 3] += offsets
            changed = _write(inst, TRANSFORM, np.ascontiguousarray(world.astype(np.float32).transpose(0, 2, 1)))  # Blender's matrices are column-major
            if inst.selected:
                shown = np.full(n, bool(inst.visible))
                for part in inst.visible:
                    shown &= values[:, part][:, 0] != 0
                changed |= _write(inst, VISIBLE, shown)
            if inst.color is not None:
                rgba = np.ones((n, 4), dtype=np.float32)
                given = values[:, inst.color]
                rgba[:, : given.shape[1]] = given
                changed |= _write(inst, COLOR, rgba)
            if changed:
                inst.mesh.update_tag()  # the depsgraph evaluates its modifier again


def _write(inst: _Instancer, name: str, array: np.ndarray) -> bool:
    last = inst.last.get(name)
    if last is not None and np.array_equal(last, array):
        return False
    inst.mesh.attributes[name].data.foreach_set("color" if name == COLOR else "value", array.ravel())
    inst.last[name] = array
    return True


def _matrix(m: Any) -> np.ndarray:
    return np.array([list(row) for row in m], dtype=np.float64)


def _basis(node: _Node, values: np.ndarray, n: int) -> np.ndarray:
    """Each env's ``matrix_basis`` of the node: translation @ Euler XYZ rotation @ scale, ``(N, 4, 4)``."""
    def column(prop: str, fixed: np.ndarray) -> np.ndarray:
        part = node.slices.get(prop)
        if part is None:
            return np.broadcast_to(fixed, (n, 3))
        return np.broadcast_to(values[:, part], (n, 3))  # a scale of one value scales every axis

    loc, rot, scale = column("location", node.location), column("rotation", node.rotation), column("scale", node.scale)
    cx, cy, cz = np.cos(rot).T
    sx, sy, sz = np.sin(rot).T
    out = np.zeros((n, 4, 4))
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = cy * cz, sx * sy * cz - cx * sz, cx * sy * cz + sx * sz
    out[:, 1, 0], out[:, 1, 1], out[:, 1, 2] = cy * sz, sx * sy * sz + cx * cz, cx * sy * sz - sx * cz
    out[:, 2, 0], out[:, 2, 1], out[:, 2, 2] = -sy, sx * cy, cx * cy
    out[:, :3, :3] *= scale[:, None, :]
    out[:, :3, 3] = loc
    out[:, 3, 3] = 1.0
    return out


def _node_group(name: str, obj: Any, selected: bool) -> Any:
    """Points -> Instance on Points (`obj` as an instance, the visible attribute as selection) -> Set Instance Transform."""
    group = bpy.data.node_groups.new(name, "GeometryNodeTree")
    group.interface.new_socket(name="Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket(name="Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    inputs, outputs = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    info = nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "ORIGINAL"  # the mesh in its own space: the transform attribute is its whole world matrix
    info.inputs["Object"].default_value = obj
    info.inputs["As Instance"].default_value = True  # an instance of the object: Cycles keeps its geometry between steps
    on_points = nodes.new("GeometryNodeInstanceOnPoints")
    links.new(inputs.outputs[0], on_points.inputs["Points"])
    links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    if selected:
        links.new(_named(nodes, "BOOLEAN", VISIBLE), on_points.inputs["Selection"])
    transform = nodes.new("GeometryNodeSetInstanceTransform")
    links.new(on_points.outputs["Instances"], transform.inputs["Instances"])
    links.new(_named(nodes, "FLOAT4X4", TRANSFORM), transform.inputs["Transform"])
    links.new(transform.outputs["Instances"], outputs.inputs[0])
    return group


def _named(nodes: Any, data_type: str, name: str) -> Any:
    node = nodes.new("GeometryNodeInputNamedAttribute")
    node.data_type = data_type
    node.inputs["Name"].default_value = name
    return node.outputs["Attribute"]


def _read_instance_color(material: Any) -> None:
    """The material's bound-colour sockets (:func:`color_sockets`) read each instance's colour attribute."""
    sockets = color_sockets(material)
    if sockets is None:
        return  # the renderer's colour setter said why (a spec error) when it compiled the bindings
    target, alpha = sockets
    nodes, links = material.node_tree.nodes, material.node_tree.links
    attribute = nodes.new("ShaderNodeAttribute")
    attribute.attribute_type = "INSTANCER"
    attribute.attribute_name = COLOR
    links.new(attribute.outputs["Color"], target)
    if alpha is not None:
        links.new(attribute.outputs["Alpha"], alpha)
