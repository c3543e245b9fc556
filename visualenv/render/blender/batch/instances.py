"""A batch's meshes as Geometry Nodes instances, their poses written from numpy: :class:`InstancedCopies`.

Moving N linked duplicates of each moving object costs Blender a Python write,
a depsgraph evaluation and a Cycles sync per copy. And every object in the
scene, moving or not, adds to Blender's update of a moved one
(results/benchmarks/batched-scene-update.md). Here
each mesh is one *instancer*: a mesh of N points (one per env) whose Geometry
Nodes modifier puts an instance of the original mesh on every point and gives
it the point's 4x4 transform attribute as its world matrix. A step computes
every env's world matrices in numpy from the binding values (location, Euler
XYZ rotation, scale, down the chain of parents, then the env's grid place) and
writes each attribute with one ``foreach_set``: no Python per env or per
copied object. Static meshes (the floor) are instanced too, posed once.

A MuJoCo model's bodies (:mod:`mjcf`: an empty per moving body, its geoms
under it in quaternion mode) are instanced the same way: a body's location and
rotation are its row of every env's ``xpos`` and ``xquat``, handed over as two
``(N, nbody, ...)`` arrays, so a batch's pose writing is a few numpy
operations and one ``foreach_set`` per geom, whatever N. The matrices are
composed in float32 as Blender composes an object's (its quaternion normalised
in float32, ``mul_m4_m4m4``'s order of sums, the anchor's place included:
:mod:`visualenv.compat.blender`), so an instance stands exactly where the
copied object stood: the same pixels.

An env's visibility is its point's selection (a hidden instance is left out),
and a bound colour an instance attribute that the mesh's own materials read
with an Attribute node (type Instancer), as each env's distraction of the
colours and its camera's turn (:meth:`InstancedCopies.write_env_attributes`). Moving instances stay instances:
realizing them, or merging the meshes, makes Cycles rebuild the geometry every
step, which costs more than syncing them; Cycles' persistent data keeps them.

Static meshes are the other way round. Once anything moves, Cycles syncs every
instance in the scene, moved or not, so
VisualCartPole's 1,024 track instances cost as much a step as its carts. A
static mesh whose every env's copy stands still (no binding moves, hides or
colours it, no camera moves the anchors) is *realized*: one mesh of every env's
copy, built once and never synced again (:func:`realizable`). Its materials
must not read where the object is (object or generated coordinates, object
info: :func:`reads_placement`), and its copies stay under
:data:`REALIZED_TRIANGLES`.

Where a moving camera moves the anchors, every static mesh moves with them and
none is realized; those a merged mesh draws with the same pixels (as for
realizing, and with the same ray settings) are joined once into one mesh in
the anchor's space, a *static group*, drawn by one instance per env at its
anchor: Goalie's eight (its goal line and columns) cost Cycles one instance
sync per env, not eight. A moving camera is computed too
(:meth:`InstancedCopies.local_matrices`): its pose per env places the env's
anchor, with no camera object per env.

What numpy cannot compute so stays a copy (:func:`removable`): lights (a light's
strength and colour are its own data, not an instance attribute), objects
with constraints, animation, deltas, rotation modes other than
XYZ and quaternion (or a bound rotation in quaternion mode), non-object parents,
aimed objects, objects whose texture is bound, a MuJoCo body whose location or
rotation is also bound, and the parents of any copied object (the copy needs its
parent).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Collection, Iterable, Mapping, Sequence

import bpy
import numpy as np

from visualenv.compat.blender import basis_matrices, check_bpy, mul_m4_m4m4, quat_to_mat3
from visualenv.render.base import BindingTarget
from visualenv.render.blender.batch.instance_nodes import (
    COLOR,
    CYCLES_SETTINGS,
    RAY_SETTINGS,
    TRANSFORM,
    VISIBLE,
    instancer_node_group,
    joined_mesh_group,
    read_instance_color,
    realizable,
    static_groups,
)
from visualenv.render.blender.scene.build import with_ancestors
from visualenv.render.blender.scene.mjcf import STRETCHED

#: the bindable properties the instanced path computes; any other binding keeps its object a copy
COMPUTED = frozenset({"location", "rotation", "scale", "visible", "color"})


def _computable(obj: Any, bound: dict[int, set[str]], aimed: set[int], posed: Collection[int] = ()) -> bool:
    """Whether numpy can compute this object's world matrix from its bindings, as Blender would (ancestors too).

    An object in `posed` (a MuJoCo body's) takes its location and rotation from MuJoCo's poses, so nothing may bind
    them; a quaternion-rotated object (the MJCF geoms and bodies) is computable while nothing binds its rotation.
    """
    # the object itself may be a camera: its pose places its env's anchor
    kinds: tuple[str, ...] = (
        "MESH",
        "EMPTY",
        "CAMERA",
    )
    while obj is not None:
        if obj.type not in kinds or obj.constraints or obj.parent_type != "OBJECT" or obj.get(STRETCHED):
            return False
        props = bound.get(obj.as_pointer(), set())
        if obj.rotation_mode not in ("XYZ", "QUATERNION") or (
            obj.rotation_mode == "QUATERNION" and "rotation" in props
        ):
            return False
        if obj.as_pointer() in posed and props & {"location", "rotation"}:
            return False
        animation = obj.animation_data
        if animation is not None and (
            animation.action is not None or len(animation.drivers) or len(animation.nla_tracks)
        ):
            return False
        if any(obj.delta_location) or any(obj.delta_rotation_euler) or tuple(obj.delta_scale) != (1.0, 1.0, 1.0):
            return False
        if obj.as_pointer() in aimed or not props <= COMPUTED:
            return False
        obj, kinds = obj.parent, ("MESH", "EMPTY")
    return True


def removable(
    copied: Sequence[Any],
    bindings: Iterable[BindingTarget],
    objects: dict[str, Any],
    aimed: Iterable[str],
    posed: Collection[int] = (),
) -> set[int]:
    """Pointers of the objects that need no copies, with only such objects (or objects never copied) under them:
    meshes and empties whose world matrices numpy computes (:func:`_computable`; the meshes are drawn as instances,
    moving or not: every object in the scene adds to Blender's update of a moved one), and cameras
    that are not aimed and that nothing moves or whose pose numpy computes too (a batch renders through its own tiles
    camera; a moving camera's pose, :meth:`InstancedCopies.local_matrices`, places its env's anchor)
    `posed`: pointers of the objects that take MuJoCo bodies' poses (:class:`InstancedCopies` computes them too)."""
    bound: dict[int, set[str]] = {}
    for target in bindings:
        if target.object in objects:
            bound.setdefault(objects[target.object].as_pointer(), set()).add(target.property)
    aimed_ptrs = {objects[name].as_pointer() for name in aimed if name in objects}
    copied_ptrs = {o.as_pointer() for o in copied}

    def dynamic(obj: Any) -> bool:
        return any(o.as_pointer() in bound for o in with_ancestors(obj))

    candidates = {
        o.as_pointer(): o
        for o in copied
        if _computable(o, bound, aimed_ptrs, posed)
        or (o.type == "CAMERA" and not dynamic(o) and o.as_pointer() not in aimed_ptrs)
    }
    changed = True
    while changed:  # drop any candidate with a copied object under it that is not removable
        changed = False
        for ptr, obj in list(candidates.items()):
            if any(c.as_pointer() in copied_ptrs and c.as_pointer() not in candidates for c in obj.children_recursive):
                del candidates[ptr]
                changed = True
    return set(candidates)


@dataclass
class _Node:
    """One object whose world matrix is computed: its fixed parts and where its bindings' values sit."""

    obj: Any
    parent: int | None  # index of its parent's node; None: it hangs from its copy's anchor
    parent_inverse: np.ndarray | None  # None: the identity
    location: np.ndarray
    rotation: np.ndarray  # Euler XYZ, or a quaternion (w, x, y, z) for an object in quaternion mode
    scale: np.ndarray
    slices: dict[str, slice] = field(default_factory=dict)  # property -> its values in the binding table
    body: int | None = None  # the MuJoCo body whose pose (a row of xpos and xquat) is its location and rotation
    # its matrix_basis ``(1, 4, 4)`` where no binding moves it (a body's: until poses come)
    basis: np.ndarray | None = None
    static: bool = False  # no binding or pose moves it or its ancestors: its world matrix is computed once
    # a static node's world matrices, its anchor's place included (recomputed when anchors move)
    world: np.ndarray | None = None


@dataclass
class _Instancer:
    """One original mesh drawn once per env: its node, its point mesh and what its points carry."""

    node: int | None  # None: a static group's, posed at each env's anchor
    mesh: Any
    # visible bindings that hide it: its own and its empty ancestors' (none: the original was hidden)
    visible: list[slice]
    selected: bool  # whether the points carry a visible attribute
    color: slice | None
    attributes: Sequence[str] = ()  # each env's own numbers (write_env_attributes)
    realized: bool = False  # every env's copy in one static mesh, built once (:func:`realizable`)
    last: dict[str, np.ndarray] = field(default_factory=dict)


class InstancedCopies:
    """The batch's removable objects (:func:`removable`), drawn by one instancer per mesh; :meth:`write` poses every env."""

    def __init__(
        self,
        collection: Any,
        anchor: Any,
        originals: Sequence[Any],
        bindings: Sequence[BindingTarget],
        objects: dict[str, Any],
        num_envs: int,
        bodies: Mapping[int, int] | None = None,
        *,
        realize_static: bool = False,
        env_attributes: Callable[[Any], Sequence[str]] = lambda obj: (),
    ) -> None:
        """`bodies`: the MuJoCo body index of each object (by pointer) that takes a body's pose (:meth:`write`'s `poses`).
        `realize_static`: whether the anchors stay where they are built, so static meshes may be realized.
        `env_attributes`: the attributes an original's materials read per env (:meth:`write_env_attributes`)."""
        check_bpy("copy of Blender's matrix arithmetic")
        self.num_envs = num_envs
        self._realize_static = realize_static
        bodies = bodies or {}
        # cameras are nodes (their poses: local_matrices), with no instancer
        originals = [o for o in originals if o.type in ("MESH", "EMPTY", "CAMERA")]
        names = {obj.as_pointer(): name for name, obj in objects.items()}
        starts: dict[tuple[str, str], slice] = {}
        start = 0
        for target in bindings:
            starts[(target.object, target.property)] = slice(start, start + target.size)
            start += target.size
        self.size = start
        order: list[Any] = []  # every removed object and its ancestors, parents first
        for obj in originals:
            for o in reversed(list(with_ancestors(obj, anchor))):
                if o not in order:
                    order.append(o)
        self._index = index = {o.as_pointer(): i for i, o in enumerate(order)}  # node of each object, by pointer
        self._nodes: list[_Node] = []
        for o in order:
            name = names.get(o.as_pointer(), "")
            slices = {prop: s for (n, prop), s in starts.items() if n == name and prop in COMPUTED}
            parent = index.get(o.parent.as_pointer()) if o.parent is not None else None
            body = bodies.get(o.as_pointer())
            static = (
                not ({"location", "rotation", "scale"} & set(slices))
                and body is None
                and (parent is None or self._nodes[parent].static)
            )
            rotation = o.rotation_quaternion if o.rotation_mode == "QUATERNION" else o.rotation_euler
            inverse = _matrix(o.matrix_parent_inverse) if parent is not None else None
            node = _Node(
                o,
                parent,
                None if inverse is None or np.array_equal(inverse, np.eye(4)) else inverse,
                np.array(o.location),
                np.array(rotation),
                np.array(o.scale),
                slices,
                body=body,
                static=static,
            )
            if not {"location", "rotation", "scale"} & set(slices):
                node.basis = _basis(node, np.zeros((1, self.size)), 1)
            self._nodes.append(node)
        self._posed = [i for i, node in enumerate(self._nodes) if node.body is not None]
        self._pose_columns = np.array([self._nodes[i].body for i in self._posed], dtype=int)
        # the anchors' world matrices the static nodes' world matrices were computed with
        self._anchors: np.ndarray | None = None
        #: whether any object takes a MuJoCo body's pose
        self.posed = bool(self._posed)
        self._env_attributes = env_attributes
        self._instancers: list[_Instancer] = []
        groups = (
            {} if realize_static else static_groups([o for o in originals if o.type == "MESH" and self._groupable(o)])
        )
        grouped = {o.as_pointer() for members in groups.values() for o in members}
        #: every static group's members' names, one list per group (one instance per env draws each group)
        self.groups = [[o.name for o in members] for members in groups.values()]
        for obj in originals:
            if obj.type == "MESH" and obj.as_pointer() not in grouped:
                self._instancers.append(self._instancer(collection, obj, index[obj.as_pointer()], anchor))
        for k, members in enumerate(groups.values()):
            self._instancers.append(self._group_instancer(collection, f"{collection.name}-static{k}", members, anchor))
        for obj in originals:
            if obj.type != "CAMERA":
                obj.hide_render = True  # its instances draw it, env 0's among them

    def _instancer(
        self, collection: Any, obj: Any, node: int | None, anchor: Any, group_attributes: Sequence[str] = ()
    ) -> _Instancer:
        """A mesh of N points under a Geometry Nodes modifier that instances `obj` on each, posed by its transform attribute
        (`node` None: a static group's object, posed at each env's anchor, its members' `group_attributes` on its points)."""
        chain = list(with_ancestors(obj, anchor)) if node is not None else []
        slices = self._nodes[node].slices if node is not None else {}
        visible = [slices["visible"]] if "visible" in slices else []
        color = slices.get("color")
        for ancestor in chain[1:]:
            slices = self._nodes[self._index[ancestor.as_pointer()]].slices
            if ancestor.type == "EMPTY" and "visible" in slices:
                visible.append(slices["visible"])  # an empty's visibility is that of everything under it
            if color is None and ancestor.type == "EMPTY" and "color" in slices:
                color = slices["color"]
        mesh = bpy.data.meshes.new(f"{obj.name}-instances")
        mesh.vertices.add(self.num_envs)
        mesh.attributes.new(TRANSFORM, "FLOAT4X4", "POINT")
        # a visible binding overrides how the original was set
        selected = bool(visible) or (obj.hide_render and node is not None)
        if selected:
            mesh.attributes.new(VISIBLE, "BOOLEAN", "POINT")
        if color is not None:
            mesh.attributes.new(COLOR, "FLOAT_COLOR", "POINT")
            for slot in obj.material_slots:
                if slot.material is not None:
                    read_instance_color(slot.material)
        attributes = list(self._env_attributes(obj)) if node is not None else list(group_attributes)
        for name in attributes:
            mesh.attributes.new(name, "FLOAT_COLOR", "POINT")
        holder = bpy.data.objects.new(f"{obj.name}-instances", mesh)
        collection.objects.link(holder)
        realized = (
            node is not None
            and self._realize_static
            and self._nodes[node].static
            and not selected
            and color is None
            and not attributes
            and realizable(obj, self.num_envs)
        )
        if realized:  # Cycles reads these from an instance's object, and from the holder of a realized mesh
            for name in RAY_SETTINGS:
                setattr(holder, name, getattr(obj, name))
            for name in CYCLES_SETTINGS:
                setattr(holder.cycles, name, getattr(obj.cycles, name))
        modifier = holder.modifiers.new("visualenv instances", "NODES")
        modifier.node_group = instancer_node_group(f"{obj.name}-instances", obj, selected, realized)
        return _Instancer(node, mesh, visible, selected, color, attributes, realized)

    def _groupable(self, obj: Any) -> bool:
        """Whether a static mesh may join its env's other static meshes in one mesh in the anchor's space (a static
        group): nothing moves, hides or colours it, and a merged mesh draws it with the same pixels (:func:`realizable`)."""
        chain = [self._nodes[self._index[o.as_pointer()]] for o in with_ancestors(obj) if o.as_pointer() in self._index]
        return (
            chain[0].static
            and not obj.hide_render
            and not any({"visible", "color"} & set(node.slices) for node in chain)
            and realizable(obj, 1)
        )

    def _group_instancer(self, collection: Any, name: str, members: Sequence[Any], anchor: Any) -> _Instancer:
        """One object whose mesh joins `members` in the anchor's space (realized once by Geometry Nodes), drawn once per
        env at its anchor: Cycles syncs one instance per env for them all, not one each."""
        merged = bpy.data.objects.new(name, bpy.data.meshes.new(name))
        collection.objects.link(merged)
        merged.matrix_world = anchor.matrix_world
        for setting in RAY_SETTINGS:  # the same in every member (static_groups)
            setattr(merged, setting, getattr(members[0], setting))
        for setting in CYCLES_SETTINGS:
            setattr(merged.cycles, setting, getattr(members[0].cycles, setting))
        modifier = merged.modifiers.new("visualenv static group", "NODES")
        modifier.node_group = joined = joined_mesh_group(name, members)
        # baked into a plain mesh once: a modifier would follow its members' transforms, and Cycles rebuild it each step
        layer = next(layer for layer in anchor.users_scene[0].view_layers if layer.use)  # the one renders use
        layer.update()
        depsgraph = layer.depsgraph
        empty, merged.data = merged.data, bpy.data.meshes.new_from_object(merged.evaluated_get(depsgraph))
        merged.data.name = name
        merged.modifiers.remove(modifier)
        bpy.data.meshes.remove(empty)
        bpy.data.node_groups.remove(joined)
        merged.hide_render = True  # its instances draw it
        attributes = list(dict.fromkeys(a for o in members for a in self._env_attributes(o)))
        return self._instancer(collection, merged, None, anchor, attributes)

    def write(
        self, values: np.ndarray, offsets: np.ndarray, poses: tuple[np.ndarray, np.ndarray] | None = None
    ) -> None:
        """Pose every env's instances: `values` the binding table ``(N, size)``, `offsets` each env's anchor, a
        translation ``(N, 3)`` or a whole matrix ``(N, 4, 4)``, `poses` every env's MuJoCo body poses, ``xpos``
        ``(N, nbody, 3)`` and ``xquat`` ``(N, nbody, 4)`` (None: the bodies stay where they were built).

        An attribute is written (and its mesh tagged for the depsgraph) only when it changed.
        """
        n = self.num_envs
        anchors = offsets.astype(np.float32)
        if self._anchors is None or anchors.shape != self._anchors.shape or not np.array_equal(anchors, self._anchors):
            self._anchors = anchors  # the anchors moved: every world matrix with them
            for node in self._nodes:
                node.world = None
        bases = self._pose_bases(poses)
        worlds: list[np.ndarray] = []
        for i, node in enumerate(self._nodes):
            if node.world is not None:
                worlds.append(node.world)
                continue
            basis = self._node_basis(i, bases, values)
            # the anchor's place included (rounding with it)
            # an anchor that only translates: the basis shifted, to the bit
            if node.parent is None and anchors.ndim == 2:
                world = np.repeat(basis, n, axis=0) if len(basis) < n else basis.copy()
                world[:, :3, 3] += anchors
            else:
                world = _child_world(anchors if node.parent is None else worlds[node.parent], node, basis)
            worlds.append(world)
            if node.static:
                node.world = world
        at_anchors = anchors if anchors.ndim == 3 else _translations(anchors)
        for inst in self._instancers:
            world = worlds[inst.node] if inst.node is not None else at_anchors
            # Blender's matrices are column-major
            changed = _write(inst, TRANSFORM, np.ascontiguousarray(world.transpose(0, 2, 1)))
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

    def local_matrices(
        self, obj: Any, values: np.ndarray, poses: tuple[np.ndarray, np.ndarray] | None = None
    ) -> np.ndarray:
        """Each env's world matrix of a removed object (a moving camera) in its copy, its anchor left out: ``(N, 4, 4)``
        float32, composed as :meth:`write` composes it (`values` and `poses` as there)."""
        n = self.num_envs
        bases = self._pose_bases(poses)
        chain: list[int] = []
        i: int | None = self._index[obj.as_pointer()]
        while i is not None:
            chain.append(i)
            i = self._nodes[i].parent
        world: np.ndarray | None = None
        for i in reversed(chain):  # from the node under the anchor down to the object
            basis = self._node_basis(i, bases, values)
            # under the anchor, which is left out: the basis itself
            world = (
                np.broadcast_to(basis, (n, 4, 4)).copy()
                if world is None
                else _child_world(world, self._nodes[i], basis)
            )
        assert world is not None
        return world

    def _node_basis(self, i: int, bases: Mapping[int, np.ndarray], values: np.ndarray) -> np.ndarray:
        """Node i's ``matrix_basis``, ``(N, 4, 4)`` or ``(1, 4, 4)`` where every env's is the same: its body's pose (in
        `bases`), its fixed basis, else composed from its bindings' values."""
        node = self._nodes[i]
        given = bases.get(i, node.basis)
        return given if given is not None else _basis(node, values, self.num_envs)

    def _pose_bases(self, poses: tuple[np.ndarray, np.ndarray] | None) -> dict[int, np.ndarray]:
        """The ``matrix_basis`` ``(N, 4, 4)`` of every node that takes a MuJoCo body's pose, by node (none without poses):
        a few numpy operations for all of them."""
        bases: dict[int, np.ndarray] = {}
        if poses is None or not self._posed:
            return bases
        n = self.num_envs
        rotations = quat_to_mat3(poses[1][:, self._pose_columns].reshape(-1, 4)).reshape(n, len(self._posed), 3, 3)
        locations = poses[0][:, self._pose_columns].astype(np.float32)
        for j, i in enumerate(self._posed):
            basis = np.zeros((n, 4, 4), dtype=np.float32)
            # rotation @ scale, as Blender's
            basis[:, :3, :3] = rotations[:, j] * self._nodes[i].scale.astype(np.float32)
            basis[:, :3, 3] = locations[:, j]
            basis[:, 3, 3] = 1.0
            bases[i] = basis
        return bases

    def write_env_attributes(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Each env's own numbers, ``(N, 4)`` float32 by attribute name, into the instances whose materials read them."""
        for inst in self._instancers:
            changed = False
            for name in inst.attributes:
                if name in arrays:
                    changed |= _write(inst, name, arrays[name])
            if changed:
                inst.mesh.update_tag()


def _write(inst: _Instancer, name: str, array: np.ndarray) -> bool:
    last = inst.last.get(name)
    if last is not None and np.array_equal(last, array):
        return False
    attribute = inst.mesh.attributes[name]
    attribute.data.foreach_set("color" if attribute.data_type == "FLOAT_COLOR" else "value", array.ravel())
    inst.last[name] = array
    return True


def _child_world(parent: np.ndarray, node: _Node, basis: np.ndarray) -> np.ndarray:
    """A node's world matrices under its parent's, as Blender composes them: (parent's world @ parent inverse) @ basis."""
    return mul_m4_m4m4(parent if node.parent_inverse is None else mul_m4_m4m4(parent, node.parent_inverse), basis)


def _translations(places: np.ndarray) -> np.ndarray:
    """``(N, 4, 4)`` float32 matrices that translate by each of ``(N, 3)`` `places`."""
    matrices = np.zeros((len(places), 4, 4), dtype=np.float32)
    matrices[:, [0, 1, 2, 3], [0, 1, 2, 3]] = 1.0
    matrices[:, :3, 3] = places
    return matrices


def _matrix(m: Any) -> np.ndarray:
    return np.array([list(row) for row in m], dtype=np.float32)


def _basis(node: _Node, values: np.ndarray, n: int) -> np.ndarray:
    """Each env's ``matrix_basis`` of the node, ``(N, 4, 4)``, from its fixed properties and its bindings' values
    (float32, as Blender keeps an object's properties), composed as Blender composes it (:func:`basis_matrices`)."""

    def column(prop: str, fixed: np.ndarray) -> np.ndarray:
        part = node.slices.get(prop)
        if part is None:
            return np.broadcast_to(fixed.astype(np.float32), (n, fixed.size))
        return np.broadcast_to(values[:, part].astype(np.float32), (n, 3))  # a scale of one value scales every axis

    # quaternion mode: nothing binds its rotation (_computable)
    rotation = node.rotation[None] if node.rotation.size == 4 else column("rotation", node.rotation)
    return basis_matrices(column("location", node.location), rotation, column("scale", node.scale))
