"""How each bound property is written into the scene: one setter per binding, compiled once per renderer.

A setter is a closure over its Blender object (no lookups per render). :class:`BindingSetters` compiles them for
:class:`~visualenv.render.blender.renderer.BlenderRenderer` (a colour or a texture writes the object's own copies of
its materials, made here); the batch renderer overrides ``_setter`` for what it draws as instances.
:func:`write_bindings` runs the setters of the values that changed, then re-aims the aimed objects.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

from visualenv.bindables import BINDABLES, WORLD_ACTOR
from visualenv.errors import RenderError, SpecError
from visualenv.render.base import RenderPlan
from visualenv.render.blender.look.materials import color_writer, make_material, texture_sets, world_writer
from visualenv.render.blender.scene.build import aim, with_ancestors
from visualenv.render.plan import CameraObject


def write_bindings(
    values: tuple,
    last: tuple | None,
    size: int,
    setters: list[tuple[int, int, Callable[[tuple], None]]],
    aimed: list[tuple[Any, str]],
    targets: dict[str, Any],
) -> None:
    """Write the binding values that differ from `last` (all of them when it is None), then re-aim the aimed objects."""
    if len(values) != size:
        raise RenderError(f"expected {size} binding values, got {len(values)}")
    for start, end, setter in setters:
        part = values[start:end]
        if last is None or part != last[start:end]:
            setter(part)
    for obj, name in aimed:
        aim(obj, targets[name])


def is_world(name: str, objects: Any) -> bool:
    """Whether an actor of this name binds the world: it is called World and no object is."""
    return name == WORLD_ACTOR and name not in objects


class BindingSetters:
    """The binding setters of a renderer: a mixin of :class:`BlenderRenderer`, which sets the scene and its objects."""

    plan: RenderPlan
    _scene: Any  # bpy Scene
    _objects: dict[str, Any]  # bpy Objects by spec (or .blend) name
    _owned: set[int]
    _size: int
    _aimed: list[tuple[Any, str]]
    _targets: dict[str, Any]

    def _compile_bindings(self) -> list[tuple[int, int, Callable[[tuple], None]]]:
        """One setter per binding target, with the slice of the values it reads."""
        plan, objects = self.plan, self._objects
        targets: dict[str, Any] = {}  # look-at point of each aimed object
        for name, spec in plan.scene.objects.items():
            if isinstance(spec, CameraObject) and spec.look_at is not None:
                targets[name] = tuple(spec.look_at)
        setters: list[tuple[int, int, Callable[[tuple], None]]] = []
        self._owned = set()  # materials copied for this pass's objects
        start = 0
        for target in plan.bindings:
            if is_world(target.object, objects):
                setter = world_writer(self._scene.world, target.property)
                assert not isinstance(setter, str), setter  # BlenderRenderer._check_names said why
                setters.append((start, start + target.size, setter))
                start += target.size
                continue
            obj = objects[target.object]
            setters.append((start, start + target.size, self._setter(target.object, obj, target.property, targets)))
            start += target.size
        self._size = start
        # aimed objects to re-aim after the setters ran: those that move, or whose parents move, or whose target does
        aimed = set(targets) | {t.object for t in plan.bindings if t.property == "look_at"}
        moved = {
            objects[t.object].as_pointer()
            for t in plan.bindings
            if BINDABLES[t.property].moves and not is_world(t.object, objects)
        }
        self._aimed = [
            (objects[name], name)
            for name in sorted(aimed)
            if any(o.as_pointer() in moved for o in with_ancestors(objects[name]))
        ]
        self._targets = targets
        return setters

    def _setter(self, name: str, obj: Any, prop: str, targets: dict[str, Any]) -> Callable[[tuple], None]:
        """The function that writes a binding's values into the scene (a closure: no lookups per render)."""
        if prop == "look_at":

            def set_look_at(v: tuple) -> None:
                targets[name] = v  # aimed in apply(), once every location is set

            return set_look_at
        if prop == "color":
            return self._color_setter(name, obj)
        if prop == "texture":
            return self._texture_setter(name, obj)
        return SETTERS[prop](obj)

    def _own_material(self, mesh_obj: Any, slot: Any) -> Any:
        """The object's own copy of the slot's material, made once per binding pass
        (a colour and a texture share it)."""
        material = slot.material
        if material is not None and material.as_pointer() in self._owned:
            return material
        copy = (
            material.copy()
            if material is not None
            else make_material(
                f"{mesh_obj.name}-bound",
                self.plan.scene.default_material,
                base_dir=self.plan.base_dir,
                source=self.plan.source,
                path=(),
                track=lambda d: d,
            )
        )
        slot.link = "OBJECT"
        slot.material = copy
        self._owned.add(copy.as_pointer())
        return copy

    def _texture_setter(self, name: str, obj: Any) -> Callable[[tuple], None]:
        """Picks the image of each texture set in the object's own copies of its materials:
        ``int(floor(v)) % len(set)``."""
        meshes = [obj] if obj.type == "MESH" else [c for c in obj.children_recursive if c.type == "MESH"]
        choosers = []
        for mesh_obj in meshes:
            for slot in mesh_obj.material_slots:
                if slot.material is None or not texture_sets(slot.material):
                    continue
                for node, images in texture_sets(self._own_material(mesh_obj, slot)):
                    choosers.append((node, images))
        if not choosers:
            raise SpecError(
                [
                    self.plan.source.diagnostic(
                        ("actors", name, "texture"),
                        f"'texture' picks one file of an image texture set, but no material of '{name}' has one: "
                        "give it material: {texture: {type: image, image: [a.png, b.png, ...]}}",
                        key=True,
                    )
                ]
            )

        def set_texture(v: tuple) -> None:
            k = math.floor(v[0])
            for node, images in choosers:
                image = images[k % len(images)]
                if node.image is not image:
                    node.image = image

        return set_texture

    def _color_setter(self, name: str, obj: Any) -> Callable[[tuple], None]:
        """A light's colour, or the colour of the object's own copies of its materials."""
        if obj.type == "LIGHT":
            data = obj.data

            def set_light_color(v: tuple) -> None:
                data.color = v[:3]

            return set_light_color
        writers = self._own_color_writers(name, obj)

        def set_color(v: tuple) -> None:
            for write in writers:
                write(v)

        return set_color

    def _own_color_writers(self, name: str, obj: Any) -> list[Callable[[Sequence[float]], None]]:
        """Writers of a bound colour into per-object copies of the materials of `obj` (and of its mesh children).

        Copies, so that the colour stays on this object.

        A textured copy gets a tint node for the colour to write; a material
        the colour cannot reach in a render (no Principled BSDF, as a .blend
        may have) is a spec error rather than a binding that silently does nothing.
        """
        meshes = [obj] if obj.type == "MESH" else [c for c in obj.children_recursive if c.type == "MESH"]
        if not meshes:
            raise SpecError(
                [
                    self.plan.source.diagnostic(
                        ("actors", name, "color"),
                        f"a bound colour sets the materials of '{name}' and the meshes under it, but it has none",
                        key=True,
                    )
                ]
            )
        out, unreachable = [], []
        for mesh_obj in meshes:
            if len(mesh_obj.material_slots) == 0:
                mesh_obj.data.materials.append(None)
            for slot in mesh_obj.material_slots:
                original = slot.material
                copy = self._own_material(mesh_obj, slot)
                write = color_writer(copy)
                if write is None:
                    unreachable.append(f"'{original.name}' of '{mesh_obj.name}'")
                else:
                    out.append(write)
        if unreachable:
            raise SpecError(
                [
                    self.plan.source.diagnostic(
                        ("actors", name, "color"),
                        "a bound colour sets a Principled BSDF's base colour, "
                        f"but material {', '.join(unreachable)} has none: "
                        "give it a Principled BSDF in Blender, or bind another property",
                    )
                ]
            )
        return out


def _set_attribute(attribute: str) -> Callable[[Any], Callable[[tuple], None]]:
    """The setter factory of a transform channel written as it is (``location``, ``rotation_euler``, ``scale``)."""

    def setter(obj: Any) -> Callable[[tuple], None]:
        def set_value(v: tuple) -> None:
            setattr(obj, attribute, v)

        return set_value

    return setter


def _set_visible(obj: Any) -> Callable[[tuple], None]:
    # an empty shows nothing itself: its visibility is that of everything under it
    shown = [obj, *obj.children_recursive] if obj.type == "EMPTY" else [obj]

    def set_visible(v: tuple) -> None:
        hide = not v[0]
        for o in shown:
            o.hide_render = hide

    return set_visible


def _set_strength(obj: Any) -> Callable[[tuple], None]:
    data = obj.data

    def set_strength(v: tuple) -> None:
        data.energy = v[0]

    return set_strength


def _set_lens(obj: Any) -> Callable[[tuple], None]:
    data = obj.data

    def set_lens(v: tuple) -> None:
        data.lens = v[0]

    return set_lens


#: setters of the bindable properties that need only the object; look_at, color and texture need the renderer's state
#: (BindingSetters._setter). Together they cover visualenv.bindables.BINDABLES (tests/spec/test_bindables.py checks).
SETTERS_WITH_STATE = ("look_at", "color", "texture")
#: the setter maker of each bindable property that needs only the object
SETTERS: dict[str, Callable[[Any], Callable[[tuple], None]]] = {
    "location": _set_attribute("location"),
    "rotation": _set_attribute("rotation_euler"),
    "scale": _set_attribute("scale"),
    "visible": _set_visible,
    "strength": _set_strength,
    "lens": _set_lens,
}
