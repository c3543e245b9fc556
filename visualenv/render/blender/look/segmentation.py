"""Segmentation observations: each pixel holds the id of the object it sees (0: nothing).

Every object that can show in a render gets an id in its ``pass_index``; a
segmentation render swaps in a view-layer material override that emits
``pass_index / 255`` (the Object Info node) over a black world, written as it is
(the 'Raw' view transform, rounded by the readback), so a pixel's byte is the id.
It renders with one sample per pixel through a box filter of Cycles' least width
(:data:`SEGMENTATION_CONFIG`): each pixel is one ray through its centre, so ids
never blend at edges and carry no noise. Lights are hidden from camera rays
meanwhile (a lamp seen directly would glow in the image).

Ids follow the scene's objects in order (a ``.blend``'s, the declared ones, then a
MuJoCo model's geoms, which take their body's name); objects that share a ``label``
share the id of the label's first object. An
object's children that the spec does not name (the parts of an imported mesh,
the children of a .blend object that are not in its scene) take its id.
"""

from __future__ import annotations

from typing import Any, Callable

import bpy

from visualenv.errors import SpecError
from visualenv.render.base import RenderPlan
from visualenv.render.blender.look.materials import override_material, set_background
from visualenv.render.blender.scene.build import BuiltScene
from visualenv.render.blender.runtime.settings import EngineConfig
from visualenv.render.plan import MeshObject, PrimitiveObject

#: one ray per pixel, through its centre (Cycles' least filter width): exact ids, the same at every render
SEGMENTATION_CONFIG = EngineConfig("cycles", 1, 0, False, "BOX", 0.01)
#: object types that put surfaces in a render
SHOWN_TYPES = ("MESH", "CURVE", "SURFACE", "META", "FONT", "CURVES", "POINTCLOUD", "VOLUME", "GREASEPENCIL")
#: the largest id a uint8 observation holds
MAX_ID = 255


def _shows(obj: Any) -> bool:
    return obj.type in SHOWN_TYPES or any(c.type in SHOWN_TYPES for c in obj.children_recursive)


def assign_ids(built: BuiltScene, plan: RenderPlan) -> dict[str, int]:
    """Give every object that shows its id (``pass_index``); returns label or object name -> id."""
    labels: dict[str, str] = {}
    for name, spec in plan.scene.objects.items():
        if isinstance(spec, (PrimitiveObject, MeshObject)) and spec.label is not None:
            labels[name] = spec.label
    # a MuJoCo model's geoms and sites take their body's name: the parts of one rigid body share an id
    physics = plan.physics
    bodies = (
        {g.name: physics.body_names[g.body] for g in (*physics.geoms, *physics.sites)} if physics is not None else {}
    )
    if physics is not None:  # each body's frame (an empty named 'body:<name>') stands for the body too
        bodies.update({f"body:{name}": name for name in physics.body_names})
    named = {obj.as_pointer() for obj in built.objects.values()}
    ids: dict[str, int] = {}
    for name, obj in built.objects.items():
        if not _shows(obj):
            continue
        key = labels.get(name, bodies.get(name, name))
        if key not in ids:
            ids[key] = len(ids) + 1
        for part in (obj, *(c for c in obj.children_recursive if c.as_pointer() not in named)):
            part.pass_index = ids[key]
    if len(ids) > MAX_ID:
        raise SpecError(
            [
                plan.source.diagnostic(
                    ("observation",),
                    f"a segmentation observation holds ids 1 to {MAX_ID}, and the scene "
                    f"has {len(ids)} objects and labels that show: give objects that need not be told apart a shared 'label'",
                )
            ]
        )
    return ids


def segmentation_material(name: str, track: Callable[[Any], Any]) -> Any:
    """An emission material of ``pass_index / 255``: the override of a segmentation render."""
    mat, nodes, links, out = override_material(name, track)
    info = nodes.new("ShaderNodeObjectInfo")
    scale = nodes.new("ShaderNodeMath")
    scale.operation = "DIVIDE"
    scale.inputs[1].default_value = float(MAX_ID)
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    links.new(info.outputs["Object Index"], scale.inputs[0])
    links.new(scale.outputs["Value"], emit.inputs["Color"])
    links.new(emit.outputs["Emission"], out.inputs["Surface"])
    mat.cycles.emission_sampling = "NONE"
    return mat


def segmentation_world(name: str, track: Callable[[Any], Any]) -> Any:
    """Black, strength 0: a ray that hits nothing is id 0."""
    world = track(bpy.data.worlds.new(name))
    set_background(world, (0.0, 0.0, 0.0, 1.0), 0.0)
    return world


class HiddenLights:
    """Hides the scene's lights from camera rays while a segmentation render runs, and shows them again after."""

    def __init__(self, scene: Any) -> None:
        self._scene = scene
        self._hidden: list[Any] = []

    def hide(self) -> None:
        self._hidden = [o for o in self._scene.objects if o.type == "LIGHT" and o.visible_camera]
        for light in self._hidden:
            light.visible_camera = False

    def show(self) -> None:
        for light in self._hidden:
            light.visible_camera = True
        self._hidden = []
