"""The scene properties an actor binding may set: one record each.

Everything that knows about bindable properties reads :data:`BINDABLES`: the
spec's ``Actor`` model (its fields and descriptions), the compiler (the type an
expression must have, which declared objects take it), the renderer (which
objects of a .blend take it, which bindings move an object so that aimed
cameras are re-aimed) and the tests that keep ``docs/spec.md`` and the Blender
backend's setters complete. Adding a property is a record here and a setter
in the backend.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from visualenv.errors import did_you_mean

#: what a binding's expression yields: 3 numbers, 3 numbers or one for all axes, 3 or 4 numbers in 0..1, a number, a condition
ValueKind = Literal["vector", "scale", "color", "number", "condition"]


@dataclass(frozen=True)
class Bindable:
    """One property an actor binding may set."""

    name: str
    value: ValueKind
    description: str
    #: Blender object types that have it (MESH, LIGHT, CAMERA, EMPTY, ...); empty: every object
    types: tuple[str, ...] = ()
    #: what it binds, for the error naming an object of another type
    binds: str = ""
    #: it changes where the object is: objects aimed at it (or parented to it) are re-aimed after it is set
    moves: bool = False


BINDABLES: dict[str, Bindable] = {
    b.name: b
    for b in (
        Bindable("location", "vector", "world position (parented: relative to the parent)", moves=True),
        Bindable("rotation", "vector", "Euler XYZ, radians", moves=True),
        Bindable("scale", "scale", "3 factors, or one for all axes", moves=True),
        Bindable(
            "visible", "condition", "a condition: hidden from every camera while false (an empty: everything under it)"
        ),
        Bindable(
            "color",
            "color",
            "material base colour (objects; on a textured material a tint that multiplies the texture) or light colour (lights)",
            types=("MESH", "LIGHT", "EMPTY"),
            binds="a material or light colour",
        ),
        Bindable(
            "strength",
            "number",
            "light strength (on the World actor: the sky's strength)",
            types=("LIGHT",),
            binds="a light's power",
        ),
        Bindable("look_at", "vector", "aim the object (a camera) at this point", moves=True),
        Bindable("lens", "number", "camera focal length (mm)", types=("CAMERA",), binds="a camera's focal length"),
        Bindable(
            "texture",
            "number",
            "which file of the material's image texture set: int(floor(value)) modulo the set's size",
            types=("MESH", "EMPTY"),
            binds="an image texture set",
        ),
    )
}


#: the actor name that binds the scene's world (unless an object has that name): its sky's strength, rotation and tint
WORLD_ACTOR = "World"
#: what a World actor may bind; rotation is a number (about the vertical axis) or three Euler angles
WORLD_PROPERTIES = ("strength", "rotation", "color")


def a_type(object_type: str) -> str:
    """'a mesh', 'an empty': a Blender object type (``bpy.types.Object.type``) in words."""
    word = object_type.lower().replace("_", " ")
    return ("an " if word[0] in "aeiou" else "a ") + word


def type_problem(prop: str, name: str, object_type: str) -> str | None:
    """Why `prop` cannot be bound on the object `name` of Blender type `object_type`; None if it can."""
    bindable = BINDABLES[prop]
    if not bindable.types or object_type in bindable.types:
        return None
    kinds = [a_type(t) for t in bindable.types]
    wanted = kinds[0] if len(kinds) == 1 else ", ".join(kinds[:-1]) + " or " + kinds[-1]
    return f"'{prop}' binds {bindable.binds}, but '{name}' is {a_type(object_type)}, not {wanted}"


def camera_problem(name: str, object_types: Mapping[str, str]) -> str | None:
    """Why the object `name` cannot be a camera of the scene whose objects have `object_types`; None if it can."""
    cameras = [n for n, t in object_types.items() if t == "CAMERA"]
    object_type = object_types.get(name)
    if object_type is None and not cameras:
        return (
            f"no camera '{name}' in the scene: the scene has no camera (objects: {', '.join(object_types) or 'none'}); "
            f"add one under scene.objects, e.g. {name}: {{camera: perspective, location: [0, -8, 4], look_at: [0, 0, 0]}}"
        )
    if object_type is None:
        return (
            f"no camera '{name}' in the scene"
            + did_you_mean(name, cameras).replace("names:", "cameras:")
            + f"; objects: {', '.join(object_types) or 'none'}"
        )
    if object_type != "CAMERA":
        return f"'{name}' is {a_type(object_type)}, not a camera" + (
            f" (cameras: {', '.join(cameras)})" if cameras else " (the scene has no camera)"
        )
    return None
