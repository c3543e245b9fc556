"""What each shader of a scene costs: the env's scene copied, one part's shader made plain in each copy, all rendered
in turn at the same states (``visualenv bench --phases``).

The parts: the ``floor`` (flat meshes: a plane has no thickness), the ``skybox`` (the world, where it is more than one
uniform Background node) and the ``bodies`` (every other mesh). A copy shares the env's meshes, lights, cameras and
materials but has objects of its own, posed from the env's objects before each render; the control copy changes
nothing. Plain: the part's meshes copied with a Diffuse BSDF of each material's viewport colour (every user of a mesh
takes the copy, so what Cycles draws as an instance stays one); a world of one Background node of the world's colour.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from visualenv.tools.render_events import CALL_PHASES, BlenderEvents, split_call

#: the parts made plain, one per copy
PARTS = ("floor", "skybox", "bodies")


@dataclass
class SceneCopy:
    """A copy of a scene with its own objects, posed from the original's by :meth:`pose`."""

    name: str
    scene: Any
    pairs: list[tuple[Any, Any]]  # (original object, its copy)
    made: list[Any] = field(default_factory=list)  # materials, worlds and meshes made for it

    def state(self) -> list[tuple[Any, bool]]:
        """Where the originals stand now: each one's local transform and whether it is hidden."""
        return [(original.matrix_basis.copy(), original.hide_render) for original, _ in self.pairs]

    def pose(self, state: list[tuple[Any, bool]]) -> None:
        """Each copy as its original stood in `state` (local transforms: parents are copied too); only what differs is
        written, as the env writes only what changed (any write tags an update)."""
        for (_, copy), (basis, hidden) in zip(self.pairs, state):
            if copy.matrix_basis != basis:
                copy.matrix_basis = basis
            if copy.hide_render != hidden:  # rebuilds the depsgraph's relations: everything synced again
                copy.hide_render = hidden

    def render(self) -> tuple[float, float]:
        """Blender's render call of this copy: its (start, end) in perf_counter seconds."""
        import bpy

        start = time.perf_counter()
        bpy.ops.render.render(scene=self.scene.name)
        return start, time.perf_counter()

    def remove(self) -> None:
        import bpy

        from visualenv.compat.blender import release_render_result

        release_render_result(self.scene)
        for _, copy in self.pairs:
            bpy.data.objects.remove(copy)
        bpy.data.scenes.remove(self.scene)
        kinds = {"World": bpy.data.worlds, "Mesh": bpy.data.meshes}
        for block in self.made:
            kinds.get(block.bl_rna.identifier, bpy.data.materials).remove(block)


def is_flat(obj: Any) -> bool:
    """A mesh with no thickness along one of its axes: a plane (MuJoCo's floor, a spec's ground)."""
    return obj.type == "MESH" and min(obj.dimensions) == 0.0


def plain_world(world: Any) -> bool:
    """Whether a world is already plain: one Background node (of an unlinked colour) into the output, or none at all."""
    if world is None or world.node_tree is None:
        return True
    kinds = sorted(node.type for node in world.node_tree.nodes)
    return kinds == ["BACKGROUND", "OUTPUT_WORLD"] and not any(
        link.to_node.type == "BACKGROUND" for link in world.node_tree.links
    )


def parts_of(scene: Any, layer: Any) -> dict[str, list[Any]]:
    """The objects (for the skybox: the world) of each part present in `scene`'s render layer; absent parts left out."""
    # a mesh's second user (scaled to nothing, unseen: scene/mjcf.keep_instanced) is made plain with the mesh
    meshes = [obj for obj in layer.objects if obj.type == "MESH" and len(obj.material_slots) and obj.visible_camera]
    found = {
        "floor": [obj for obj in meshes if is_flat(obj)],
        "skybox": [] if plain_world(scene.world) else [scene.world],
        "bodies": [obj for obj in meshes if not is_flat(obj)],
    }
    return {part: found[part] for part in PARTS if found[part]}


def _kept(made: list[Any]) -> Callable[[Any], Any]:
    """A tracker that adds each data block made to `made` (removed with the copy)."""

    def track(block: Any) -> Any:
        made.append(block)
        return block

    return track


def _diffuse(original: Any, made: list[Any]) -> Any:
    from visualenv.render.blender.look.materials import override_material

    name = f"visualenv-plain-{original.name if original is not None else 'none'}"
    mat, nodes, links, output = override_material(name, _kept(made))
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    colour = tuple(original.diffuse_color) if original is not None else (0.8, 0.8, 0.8, 1.0)
    diffuse.inputs["Color"].default_value = colour
    links.new(diffuse.outputs["BSDF"], output.inputs["Surface"])
    return mat


def _world(original: Any, made: list[Any]) -> Any:
    import bpy

    from visualenv.render.blender.look.materials import set_background

    world = bpy.data.worlds.new(f"visualenv-plain-{original.name}")
    made.append(world)
    set_background(world, (*original.color[:3], 1.0), 1.0)
    return world


def _make_plain(chosen: list[Any], pairs: list[tuple[Any, Any]], made: list[Any]) -> None:
    """The copies of `chosen` drawn with plain materials: each chosen mesh copied with them, for all its users
    (object-level material slots, or users that disagree, would keep Cycles from drawing the mesh as an instance:
    scene/mjcf.keep_instanced)."""
    plain_of: dict[str, Any] = {}

    def plain(material: Any) -> Any:
        key = material.name if material is not None else ""
        if key not in plain_of:
            plain_of[key] = _diffuse(material, made)
        return plain_of[key]

    users: dict[int, list[Any]] = {}
    for original, duplicate in pairs:
        if original.type == "MESH":
            users.setdefault(original.data.as_pointer(), []).append(duplicate)
    for mesh in {original.data for original in chosen}:
        plain_mesh = mesh.copy()
        made.append(plain_mesh)
        for i, material in enumerate(plain_mesh.materials):
            plain_mesh.materials[i] = plain(material)
        for duplicate in users[mesh.as_pointer()]:
            duplicate.data = plain_mesh
            for slot in duplicate.material_slots:  # a material linked to the object rather than its mesh
                if slot.link == "OBJECT":
                    slot.material = plain(slot.material)


def copy_scene(
    scene: Any, layer: Any, name: str, plain: str | None = None, parts: dict[str, list] | None = None
) -> SceneCopy:
    """A copy of `scene` (its settings; objects of its own for those of `layer`) with the shader of `plain` (one of
    :data:`PARTS`) made plain."""
    copy = scene.copy()
    copy.name = f"{scene.name}-{name}"
    collection = copy.collection
    for child in list(collection.children):
        collection.children.unlink(child)
    for obj in list(collection.objects):
        collection.objects.unlink(obj)
    pairs = [(obj, obj.copy()) for obj in layer.objects]
    copies = {original.name: duplicate for original, duplicate in pairs}
    for original, duplicate in pairs:
        if original.parent is not None and original.parent.name in copies:
            duplicate.parent = copies[original.parent.name]
        collection.objects.link(duplicate)
    if scene.camera is not None and scene.camera.name in copies:
        copy.camera = copies[scene.camera.name]
    made: list[Any] = []
    chosen = (parts or {}).get(plain or "", [])
    if plain == "skybox" and chosen:
        copy.world = _world(scene.world, made)
    elif chosen:
        _make_plain(chosen, pairs, made)
    return SceneCopy(name, copy, pairs, made)


def ablation(scene: Any, layer: Any, steps: int, step: Callable[[int], None], block: int = 10) -> dict[str, Any]:
    """Each part made plain in a copy of `scene`, against a control copy, at `steps` states (``step(i)`` moves the env
    to the i-th). The states come in blocks of `block`: each copy renders the block's states in turn, in an order that
    turns by one each block, after one render not timed (rendering another scene costs Cycles' persistent data: the
    first render after a switch syncs everything). Per part: the median over states of (its render call - the
    control's), in total and per phase (ms); the control's median call."""
    parts = parts_of(scene, layer)
    copies = [copy_scene(scene, layer, "control")] + [copy_scene(scene, layer, part, part, parts) for part in parts]
    events = BlenderEvents()
    rows: list[list[dict[str, float]]] = [[] for _ in copies]
    try:
        done = turn = 0
        while done < steps:
            states = []
            for i in range(done, min(steps, done + block)):
                step(i)
                states.append(copies[0].state())
            for k in range(len(copies)):
                j = (turn + k) % len(copies)
                copy = copies[j]
                copy.pose(states[-1])
                copy.render()
                for state in states:
                    copy.pose(state)
                    events.clear()
                    with events:
                        start, end = copy.render()
                    split = split_call(start, end, events.events)
                    rows[j].append({"call": end - start} | {phase: split.total(phase) for phase in CALL_PHASES})
            done += len(states)
            turn += 1
    finally:
        for copy in copies:
            copy.remove()
    control = rows[0]
    out: dict[str, Any] = {
        "control_call_ms": 1000 * float(np.median([r["call"] for r in control])) if control else 0.0,
        "objects": {part: len(objects) for part, objects in parts.items()},
        "parts": {},
    }
    for copy, measured in zip(copies[1:], rows[1:]):
        out["parts"][copy.name] = {
            f"{key}_ms": 1000 * float(np.median([m[key] - c[key] for m, c in zip(measured, control)]))
            for key in ("call", *CALL_PHASES)
        }
    return out
