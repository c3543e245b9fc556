"""The renderer interface the env talks to, and what a renderer is given.

The compiler produces a :class:`~visualenv.render.plan.RenderPlan` (``Program.render_plan()``): the
scene description, the observation cameras, the render settings and the list
of binding targets, in render's own types. Each render is given :class:`~visualenv.render.frames.Frames`:
the binding values of N envs (a flat tuple each, in :attr:`RenderPlan.bindings` order), their physics
poses and distractions. A renderer turns those into pixels; it knows nothing of rewards or episodes.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Callable, Literal, Mapping, get_args

import numpy as np
from gymnasium import spaces

from visualenv.render.frames import Frames
from visualenv.render.profile import Profile
from visualenv.render.plan import BindingTarget, CameraView, RenderPlan  # noqa: F401 - BindingTarget and RenderPlan re-exported

CHANNELS = {"rgb": 3, "grayscale": 1, "depth": 1, "segmentation": 1}


def view_space(view: CameraView) -> spaces.Box:
    """The observation space of one camera: (height, width, channels) bytes."""
    width, height = view.resolution
    return spaces.Box(0, 255, (height, width, CHANNELS[view.color]), np.uint8)


class Renderer(ABC):
    """Turns the state of N envs (:class:`~visualenv.render.frames.Frames`) into observation arrays and views, N first.

    A renderer is built for :attr:`n` envs: a single env's is built for one
    (``cls(plan, options)`` by :func:`create_renderer`), a batch's for any N. The plan's
    settings already hold the options' overrides; the options add the readback.
    """

    plan: RenderPlan
    #: how many envs each call renders (the rows of its Frames)
    n: int = 1
    #: where a render's time goes, recorded while set (:class:`~visualenv.render.profile.Profile`; None: nothing timed)
    profile: Profile | None = None

    @abstractmethod
    def render(self, frames: Frames) -> np.ndarray | dict[str, np.ndarray]:
        """Every observation camera for the envs of `frames`: ``(N, H, W, C)`` uint8, or a dict of those by
        observation key for several cameras (N: ``len(frames.envs)`` where envs are chosen)."""

    @abstractmethod
    def render_view(self, frames: Frames) -> np.ndarray:
        """The high-resolution RGB view of each env of `frames`, ``(N, H, W, 3)`` uint8."""

    @abstractmethod
    def close(self) -> None:
        """Free everything this renderer created (idempotent)."""


Readback = Literal["auto", "memory", "file"]
READBACKS: tuple[str, ...] = get_args(Readback)
#: the render fields an option of the same name overrides
RENDER_OVERRIDES = ("engine", "samples", "device", "threads", "noise")


@dataclass(frozen=True)
class RendererOptions:
    """What a renderer is told besides the plan: overrides of the spec's render settings given in Python, and the readback.

    Made once from the keyword options of ``visualenv.make`` (or ``VisualEnv(renderer_options=...)``),
    where the env checks the overrides as the spec's ``render`` section checks them
    (:func:`visualenv.compiler.render_plan.checked_options`), and merged into the plan's settings once
    (:meth:`RenderPlan.with_options`), so a backend reads one ``RenderSettings`` and never looks at loose
    keyword arguments.

    ``readback`` says how pixels leave Blender: ``"memory"`` (Cycles only: the render result
    copied in place), ``"file"`` (a BMP in shared memory, any engine) or ``"auto"`` (memory where possible).
    """

    engine: str | None = None
    samples: int | None = None
    device: str | None = None
    threads: int | None = None
    noise: str | None = None
    readback: Readback = "auto"

    def __post_init__(self) -> None:
        if self.readback not in READBACKS:
            raise ValueError(f"unknown readback {self.readback!r}: use {', '.join(READBACKS)}")

    @classmethod
    def parse(cls, options: "Mapping[str, Any] | RendererOptions | None") -> "RendererOptions":
        """The options of a ``**renderer_options`` mapping (an unknown name is a TypeError listing the known ones)."""
        if isinstance(options, RendererOptions):
            return options
        options = dict(options or {})
        known = (*RENDER_OVERRIDES, "readback")
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise TypeError(f"unknown renderer option(s) {', '.join(unknown)}: use {', '.join(known)}")
        return cls(**options)

    def overrides(self) -> dict[str, Any]:
        """The render fields these options set."""
        return {name: getattr(self, name) for name in RENDER_OVERRIDES if getattr(self, name) is not None}


#: the spec's settings as they are, the readback chosen by the renderer
DEFAULT_OPTIONS = RendererOptions()


#: the default backend, as a ``module:attribute`` entry point (imported on first render, so state-only envs never load bpy)
BLENDER_BACKEND = "visualenv.render.blender:BlenderRenderer"
#: Cycles' device backends, as `visualenv info` lists them
CYCLES_BACKENDS = ("CPU", "CUDA", "OPTIX", "HIP", "METAL", "ONEAPI")


def load_backend(entry_point: str) -> Callable[..., Renderer]:
    """The renderer class (or factory) named by ``module:attribute``, as Gymnasium's registry loads env creators."""
    module_name, _, attribute = entry_point.partition(":")
    if not module_name or not attribute:
        raise ValueError(f"renderer backend {entry_point!r} is not of the form 'module:attribute'")
    return getattr(importlib.import_module(module_name), attribute)


def create_renderer(
    plan: RenderPlan, backend: str = BLENDER_BACKEND, options: RendererOptions = DEFAULT_OPTIONS
) -> Renderer:
    """The renderer of `backend` for `plan`, its settings merged with `options` (a backend is called as ``cls(plan, options)``)."""
    return load_backend(backend)(plan.with_options(options), options)
