"""What the env's copy of a user's scene keeps: the binding wins over whatever the .blend holds.

A .blend made in Blender's GUI can carry animation on an object the spec binds, a simulation that
would move it, a view layer that is switched off or a collection excluded from it. These functions
change only the renderer's own (appended) copy of the scene; the file on disk is never written.
"""

from __future__ import annotations

from typing import Any, Iterable, Iterator

#: the Blender data paths a binding writes, per bound property (on the object, or on its data)
OBJECT_CHANNELS = {
    "location": ("location",),
    "rotation": ("rotation_euler", "rotation_quaternion", "rotation_axis_angle"),
    "look_at": ("rotation_euler", "rotation_quaternion", "rotation_axis_angle"),
    "scale": ("scale",),
    "visible": ("hide_render",),
}
DATA_CHANNELS = {"strength": ("energy",), "lens": ("lens",), "color": ("color",)}

#: constraints that set only some of the transform (any other kind sets all of it)
_CONSTRAINT_SETS = {
    "rotation": {"TRACK_TO", "DAMPED_TRACK", "LOCKED_TRACK", "COPY_ROTATION", "LIMIT_ROTATION"},
    "location": {"COPY_LOCATION", "LIMIT_LOCATION", "LIMIT_DISTANCE", "FLOOR"},
    "scale": {"COPY_SCALE", "LIMIT_SCALE", "MAINTAIN_VOLUME"},
}
_TRANSFORM = {"location": "location", "rotation": "rotation", "look_at": "rotation", "scale": "scale"}


def constraint_sets(kind: str) -> set[str]:
    """The transform parts ('location', 'rotation', 'scale') a constraint of this kind overrides."""
    parts = {part for part, kinds in _CONSTRAINT_SETS.items() if kind in kinds}
    return parts or {"location", "rotation", "scale"}


def animated_fcurves(anim: Any) -> Iterator[Any]:
    """The F-curves of an animation data block: its action's and its NLA strips' (the slots they use)."""
    from bpy_extras.anim_utils import action_get_channelbag_for_slot

    if anim is None:
        return
    pairs = [(anim.action, anim.action_slot)]
    pairs += [(strip.action, strip.action_slot) for track in anim.nla_tracks for strip in track.strips]
    for action, slot in pairs:
        if action is None or slot is None:
            continue
        bag = action_get_channelbag_for_slot(action, slot)
        if bag is not None:
            yield from bag.fcurves


def free_bound_channels(obj: Any, properties: Iterable[str]) -> list[str]:
    """Mute the keyframes, NLA, drivers and constraints that would overwrite the bound `properties` at render time.

    Returns what was muted, as 'Ball: location keyframes' lines.
    """
    properties = set(properties)
    muted: list[str] = []

    def mute(owner: Any, paths: set[str], label: str) -> None:
        anim = getattr(owner, "animation_data", None)
        if not paths or anim is None:
            return
        for fcurve in animated_fcurves(anim):
            if fcurve.data_path in paths and not fcurve.mute:
                fcurve.mute = True
                muted.append(f"{label}: {fcurve.data_path}[{fcurve.array_index}] keyframes")
        for fcurve in anim.drivers:
            if fcurve.data_path in paths and not fcurve.mute:
                fcurve.mute = True
                muted.append(f"{label}: {fcurve.data_path}[{fcurve.array_index}] driver")

    mute(obj, {p for prop in properties for p in OBJECT_CHANNELS.get(prop, ())}, obj.name)
    if obj.data is not None and obj.type in ("LIGHT", "CAMERA"):
        mute(obj.data, {p for prop in properties for p in DATA_CHANNELS.get(prop, ())}, obj.name)
    bound_parts = {_TRANSFORM[p] for p in properties if p in _TRANSFORM}
    for con in obj.constraints:
        if con.enabled and bound_parts & constraint_sets(con.type):
            con.enabled = False
            muted.append(f"{obj.name}: constraint '{con.name}' ({con.type})")
    return muted


def render_layer(scene: Any) -> Any:
    """The view layer renders use: the first one switched on in the file (else the first); the others are switched off."""
    layers = list(scene.view_layers)
    chosen = next((layer for layer in layers if layer.use), layers[0])
    for layer in layers:
        layer.use = layer is chosen
    return chosen


def include_collections_of(layer: Any, objects: Iterable[Any]) -> list[str]:
    """Include in `layer` (and show in renders) the collections holding `objects`; returns the names changed."""
    wanted = {c.as_pointer() for obj in objects for c in obj.users_collection}
    changed: list[str] = []

    def visit(lc: Any, path: list[Any]) -> None:
        if lc.collection.as_pointer() in wanted:
            for on_path in [*path, lc]:
                if on_path.exclude or on_path.collection.hide_render:
                    on_path.exclude = False
                    on_path.collection.hide_render = False
                    changed.append(on_path.collection.name)
        for child in lc.children:
            visit(child, [*path, lc])

    for child in layer.layer_collection.children:
        visit(child, [])
    return changed


def stop_simulations(scene: Any) -> list[str]:
    """No rigid body world and no emitted particles in renders (hair stays); returns what was stopped."""
    stopped = []
    world = scene.rigidbody_world
    if world is not None and world.enabled:
        world.enabled = False
        stopped.append("rigid body world")
    for obj in scene.objects:
        for mod in obj.modifiers:
            if mod.type == "PARTICLE_SYSTEM" and mod.show_render and mod.particle_system.settings.type == "EMITTER":
                mod.show_render = False
                stopped.append(f"{obj.name}: particle system '{mod.name}'")
    return stopped
