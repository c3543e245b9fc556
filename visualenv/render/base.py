"""The renderer interface the env talks to, and what a renderer is given.

The compiler produces a :class:`RenderPlan` (``Program.render_plan()``): the
scene description, the observation cameras, the render settings and the list
of binding targets. Before each render the env passes the current binding values
(a flat tuple in :attr:`RenderPlan.bindings` order). A renderer turns those
into pixels; it knows nothing of rewards or episodes.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from gymnasium import spaces

from visualenv.spec.models import CameraView, Observation, Render, Scene
from visualenv.spec.source import SourceMap

CHANNELS = {"rgb": 3, "grayscale": 1, "depth": 1}


def view_space(view: CameraView) -> spaces.Box:
    width, height = view.resolution
    return spaces.Box(0, 255, (height, width, CHANNELS[view.color]), np.uint8)


def observation_space(observation: Observation) -> spaces.Space:
    """Box for one camera, Dict keyed by name for several."""
    views = observation.views()
    if observation.cameras is None:
        return view_space(next(iter(views.values())))
    return spaces.Dict({key: view_space(view) for key, view in views.items()})


@dataclass(frozen=True)
class BindingTarget:
    """One scene property a renderer sets before each render."""

    object: str
    property: str  # a key of visualenv.spec.bindables.BINDABLES
    size: int  # how many values the binding function yields for it (1 for scalars)


@dataclass(frozen=True)
class RenderPlan:
    """Everything a renderer needs, produced by the compiler (``Program.render_plan()``)."""

    scene: Scene
    views: dict[str, CameraView]  # observation cameras by observation key
    single: bool  # one camera (Box) rather than several (Dict)
    settings: Render
    bindings: tuple[BindingTarget, ...]
    base_dir: Path
    source: SourceMap
    cameras: tuple[tuple[tuple, str], ...] = ()  # every camera the spec names, with its field's path (Spec.camera_uses)

    @property
    def view_camera(self) -> str | None:
        """The camera of the human view: render.view.camera, else the first observation camera."""
        if self.settings.view.camera:
            return self.settings.view.camera
        return next(iter(self.views.values())).camera if self.views else None


class Renderer(ABC):
    """Turns binding values into observation arrays and a human view."""

    plan: RenderPlan

    @abstractmethod
    def render_observation(self, values: Sequence[Any]) -> np.ndarray | dict[str, np.ndarray]:
        """Apply `values` to the bound properties and render every observation camera."""

    @abstractmethod
    def render_view(self, values: Sequence[Any]) -> np.ndarray:
        """Apply `values` and render the high-resolution RGB view, (H, W, 3) uint8."""

    @abstractmethod
    def close(self) -> None:
        """Free everything this renderer created (idempotent)."""


#: keyword options a renderer accepts (documented on :class:`BlenderRenderer`)
RENDERER_OPTIONS = ("device", "threads", "engine", "samples", "readback")
READBACKS = ("auto", "memory", "file")


def check_renderer_options(options: dict[str, Any]) -> None:
    """Fail at ``make()`` time, not at the first render, on an option the renderer would refuse."""
    unknown = sorted(set(options) - set(RENDERER_OPTIONS))
    if unknown:
        raise TypeError(f"unknown renderer option(s) {', '.join(unknown)}: use {', '.join(RENDERER_OPTIONS)}")
    readback = options.get("readback", "auto")
    if readback not in READBACKS:
        raise ValueError(f"unknown readback {readback!r}: use {', '.join(READBACKS)}")


#: the default backend, as a ``module:attribute`` entry point (imported on first render, so state-only envs never load bpy)
BLENDER_BACKEND = "visualenv.render.blender:BlenderRenderer"


def load_backend(entry_point: str) -> Callable[..., Renderer]:
    """The renderer class (or factory) named by ``module:attribute``, as Gymnasium's registry loads env creators."""
    module_name, _, attribute = entry_point.partition(":")
    if not module_name or not attribute:
        raise ValueError(f"renderer backend {entry_point!r} is not of the form 'module:attribute'")
    return getattr(importlib.import_module(module_name), attribute)


def create_renderer(plan: RenderPlan, backend: str = BLENDER_BACKEND, **options: Any) -> Renderer:
    """The renderer of `backend` for `plan`, given the renderer `options`."""
    return load_backend(backend)(plan, **options)
