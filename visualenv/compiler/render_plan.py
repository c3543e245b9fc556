"""The spec's models turned into render's plan types (:mod:`visualenv.render.plan`), once per program.

Each plan type has the fields of the spec model of the same name that a renderer reads; lists become
tuples and the spec's defaults are filled in, so render/ reads the plan without the spec.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping

from gymnasium import spaces
from pydantic import BaseModel

from visualenv.render import plan as p
from visualenv.render.base import RendererOptions, view_space
from visualenv.spec import models as m
from visualenv.spec.options import check_make_options

#: each spec model and the plan type made of it
PLAN_TYPES: dict[type[BaseModel], type] = {
    m.Texture: p.Texture,
    m.Material: p.Material,
    m.Craters: p.Craters,
    m.PrimitiveObject: p.PrimitiveObject,
    m.MeshObject: p.MeshObject,
    m.LightObject: p.LightObject,
    m.CameraObject: p.CameraObject,
    m.EmptyObject: p.EmptyObject,
    m.Sensor: p.Sensor,
    m.CameraView: p.CameraView,
    m.ViewSettings: p.ViewSettings,
    m.RenderSettings: p.RenderSettings,
    m.Distractions: p.Distractions,
    m.VideoBackground: p.VideoBackground,
}


def plain(value: Any) -> Any:
    """`value` in plan types: a model as its plan type, lists as tuples, dicts item by item."""
    if isinstance(value, BaseModel):
        return to_plan(value)
    if isinstance(value, list):
        return tuple(plain(v) for v in value)
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    return value


def to_plan(model: BaseModel, **given: Any) -> Any:
    """The plan type of `model`, its fields read from the model unless `given`."""
    kind = PLAN_TYPES[type(model)]
    return kind(
        **{
            f.name: given[f.name] if f.name in given else plain(getattr(model, f.name))
            for f in dataclasses.fields(kind)
        }
    )


def world_plan(world: m.World) -> p.World:
    r = world.rotation
    rotation = (r[0], r[1], r[2]) if isinstance(r, list) else r
    return p.World(tint=tuple(world.tint()), strength=world.strength, image=world.image, rotation=rotation)


def scene_plan(scene: m.Scene) -> p.Scene:
    default_material = to_plan(m.Material())
    objects = {
        name: to_plan(obj, material=plain(obj.material or m.Material()))
        if isinstance(obj, m.PrimitiveObject)
        else to_plan(obj)
        for name, obj in scene.objects.items()
    }
    return p.Scene(
        file=scene.file,
        file_scene=scene.file_scene,
        objects=objects,
        world=world_plan(scene.world) if scene.world is not None else None,
        default_world=world_plan(m.World()),
        default_material=default_material,
        max_image_pixels=scene.max_image_pixels,
    )


def views_plan(observation: m.Observation | None) -> dict[str, p.CameraView]:
    """The observation cameras by observation key."""
    return {key: to_plan(view) for key, view in observation.views().items()} if observation is not None else {}


def distractions_plan(distractions: m.Distractions | None) -> p.Distractions | None:
    return to_plan(distractions) if distractions is not None else None


def observation_space(observation: m.Observation) -> spaces.Space:
    """Box for one camera, Dict keyed by name for several."""
    views: Mapping[str, p.CameraView] = views_plan(observation)
    if observation.cameras is None:
        return view_space(next(iter(views.values())))
    return spaces.Dict({key: view_space(view) for key, view in views.items()})


def checked_options(given: Mapping[str, Any] | RendererOptions | None) -> RendererOptions:
    """The renderer options of `given` (:meth:`RendererOptions.parse`), a value the spec's ``render`` would refuse
    refused now, in its words, and not at the first render."""
    options = RendererOptions.parse(given)
    check_make_options(**options.overrides())
    return options
