"""The batch's copies of the scene: env k's objects under an anchor at k's place on a grid of copies.

Copy k holds linked duplicates (sharing meshes and materials) of what the batch cannot draw as instances
(:mod:`instances`), under an anchor empty at k's grid place, farther from the next copy than any camera sees
(:func:`copy_spacing`). Sun lights are directional: one serves every copy, except a sun bound to the state:
each copy has its own, which lights and shadows only that copy's objects (Cycles' light linking, :func:`link_lights`).
Point, spot and area lights, one per copy, are linked the same way up to 63 copies (:func:`linked_local_lights`).
"""

from __future__ import annotations

import warnings
from typing import Any

import bpy
from mathutils import Matrix, Vector

from visualenv.render.batch_limits import MAX_LINKED_ENVS
from visualenv.render.blender.look.materials import SKYBOX
from visualenv.render.blender.scene.build import BuiltScene, aim


class Copy:
    """One env's objects: its anchor, its binding setters and what they last wrote."""

    def __init__(self, anchor: Any, objects: dict[str, Any]) -> None:
        self.anchor = anchor  # None: nothing of this env is copied (its objects are instances), as with a camera that does not move
        self.objects = objects
        self.setters: list = []
        self.aimed: list = []
        self.targets: dict[str, Any] = {}
        self.last: tuple | None = None


def grid_offset(k: int, cols: int, spacing: float) -> Vector:
    """Where copy k's anchor stands: column ``k % cols``, row ``k // cols`` of a grid `spacing` apart."""
    return Vector(((k % cols) * spacing, (k // cols) * spacing, 0.0))


def copy_spacing(scene: Any, reach: float) -> float:
    """How far apart copies stand: farther than any camera sees (`reach`, the cameras' farthest clip), plus the scene's size."""
    size = 0.0
    for obj in scene.objects:
        if is_sun(obj):
            continue
        corners = [obj.matrix_world @ Vector(c) for c in obj.bound_box] or [obj.matrix_world.translation]
        size = max(size, *(c.length for c in corners))
    return float(reach + 2 * size + 10.0)


def make_copy(
    k: int,
    built: BuiltScene,
    originals: list[Any],
    places: dict[int, Matrix],
    offset: Vector,
    *,
    removed: set[int],
    own_lights: set[int],
) -> Copy:
    """Copy k: linked duplicates of the originals (copy 0 is the originals) under an anchor at `offset`, k's grid place.

    An object whose parent is not copied with it hangs from the anchor at its own world place (`places`).
    Objects drawn as instances (pointers in `removed`) are not copied: a copy with nothing else to copy has no anchor
    (None) and no objects of its own. Each copy's light has its own light data (a bound strength is written copy by
    copy); a light of each copy's own (in `own_lights`) lights only its copy (:func:`link_lights`).
    """
    scene = built.scene
    if k and all(o.as_pointer() in removed for o in originals):
        return Copy(None, dict(built.objects))
    collection = bpy.data.collections.new(f"{scene.name}-env{k}")
    scene.collection.children.link(collection)
    anchor = bpy.data.objects.new(f"{scene.name}-anchor{k}", None)
    collection.objects.link(anchor)
    anchor.location = offset
    if k == 0:
        mapping = {o.as_pointer(): o for o in originals}
    else:
        mapping = {}
        for original in originals:
            if original.as_pointer() in removed:
                continue  # drawn by its instancer
            duplicate = original.copy()
            if original.type == "LIGHT":
                duplicate.data = original.data.copy()  # its own strength and colour, written copy by copy
            collection.objects.link(duplicate)
            mapping[original.as_pointer()] = duplicate
        for duplicate in mapping.values():
            remap_references(duplicate, mapping)
    for original in originals:
        obj = mapping.get(original.as_pointer())
        if obj is None:
            continue
        if original.parent is None or original.parent.as_pointer() not in mapping:
            obj.parent = anchor
            obj.matrix_parent_inverse = Matrix.Identity(4)
            obj.matrix_basis = places[original.as_pointer()]
    if own_lights:
        link_lights(k, scene, originals, mapping, own_lights)
    objects = {name: mapping.get(obj.as_pointer(), obj) for name, obj in built.objects.items()}
    return Copy(anchor, objects)


def link_lights(k: int, scene: Any, originals: list[Any], mapping: dict[int, Any], own_lights: set[int]) -> None:
    """Copy k's own lights light and shadow only copy k's objects (a receiver and blocker collection of them)."""
    receivers = bpy.data.collections.new(f"{scene.name}-lit{k}")
    lights = []
    for original in originals:
        obj = mapping[original.as_pointer()]
        if original.as_pointer() in own_lights:
            lights.append(obj)
        else:
            receivers.objects.link(obj)
    for light in lights:
        light.light_linking.receiver_collection = receivers
        light.light_linking.blocker_collection = receivers


def linked_local_lights(copied: list[Any], num_envs: int) -> set[int]:
    """The copied point, spot and area lights (by pointer) to light only their own copy: all of them from 2 to
    MAX_LINKED_ENVS envs, else none.

    At 1 sample Cycles' light tree picks one light per shading point, and it cannot rule out the other copies'
    lights from the bounds of a cluster of them: it spends some samples on lights that reach nothing there, and a
    tile's light is missing or doubled in places (a spot-lit DMC task's worst tile, 8 to 16 envs, was 4 to 43 levels
    off on average: results/benchmarks/batch-lights.md). Linked, each copy's objects see only their copy's lights.
    Light linking tells 64 light sets apart (:data:`~visualenv.render.batch_limits.MAX_LINKED_ENVS`); past that, the
    lights stay shared by the tree.
    """
    if not 1 < num_envs <= MAX_LINKED_ENVS:
        return set()
    return {o.as_pointer() for o in copied if is_local_light(o)}


def warn_shared_lights(copied: list[Any], num_envs: int) -> None:
    """Past MAX_LINKED_ENVS envs the copied point, spot and area lights cannot be linked to their copies: say that the
    tiles are lit otherwise than each env alone (:func:`linked_local_lights`)."""
    if num_envs <= MAX_LINKED_ENVS:
        return
    lamps = sorted(o.name for o in copied if is_local_light(o))
    if lamps:
        warnings.warn(
            f"visualenv: a batch of {num_envs} envs shares light {lamps[0]!r} of every env in Cycles' light tree "
            f"(light linking tells at most {MAX_LINKED_ENVS} envs apart), so its tiles are lit otherwise than each "
            f"env alone; keep at most {MAX_LINKED_ENVS} envs per batch (make_vec(..., batched=True, workers=K) "
            "splits them into K batches)",
            RuntimeWarning,
            stacklevel=3,
        )


def aim_copy(copy: Copy) -> None:
    """Aim a copy's aimed objects at their targets in the copy's own frame (a look_at point is where it is in one env):
    the anchor's place, a grid offset, must not turn them. Aimed with the anchor at the origin (it only translates), the
    rotations are those of one env to the bit, where aiming at the offset target rounds at the offset's magnitude."""
    if not copy.aimed:
        return
    place = copy.anchor.matrix_basis.copy()
    copy.anchor.matrix_basis = Matrix.Identity(4)
    try:
        for obj, name in copy.aimed:
            aim(obj, copy.targets[name])
    finally:
        copy.anchor.matrix_basis = place


def one_colour(world: Any) -> bool:
    """Whether a world lights in one colour from every direction: no texture node (an image or a procedural sky) in
    its shader, but a model's skybox (seen by camera rays only)."""
    tree = getattr(world, "node_tree", None) if world is not None else None
    return tree is None or not any(
        node.bl_idname.startswith("ShaderNodeTex") and node.name != SKYBOX for node in tree.nodes
    )


def is_sun(obj: Any) -> bool:
    """A sun light: directional, so one serves every copy unless the state binds it."""
    return bool(obj.type == "LIGHT" and obj.data.type == "SUN")


def is_local_light(obj: Any) -> bool:
    """A point, spot or area light: at a place, so each copy has its own and the light tree weighs it by where it is."""
    return bool(obj.type == "LIGHT" and obj.data.type in ("POINT", "SPOT", "AREA"))


def hidden(obj: Any) -> bool:
    """An object no render shows: hidden itself, or in hidden collections only."""
    return bool(obj.users_collection) and all(c.hide_render for c in obj.users_collection)


def remap_references(obj: Any, mapping: dict[int, Any]) -> None:
    """Point a duplicate's parent, constraint targets and modifier objects at the duplicates of its own copy."""

    def swap(value: Any) -> Any:
        return mapping.get(value.as_pointer(), value) if value is not None else None

    obj.parent = swap(obj.parent) if obj.parent is not None else None
    for constraint in obj.constraints:
        if hasattr(constraint, "target"):
            constraint.target = swap(constraint.target)
    for modifier in obj.modifiers:
        for attribute in ("object", "offset_object", "mirror_object", "target"):
            if hasattr(modifier, attribute) and isinstance(getattr(modifier, attribute), bpy.types.Object):
                setattr(modifier, attribute, swap(getattr(modifier, attribute)))
