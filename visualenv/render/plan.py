"""What a renderer is given: the render plan, in render's own plain types.

The compiler builds a :class:`RenderPlan` once from the spec (``Program.render_plan()``,
:mod:`visualenv.compiler.render_plan`): each type here holds the fields a renderer reads of
the spec model of the same name, with the spec's defaults already filled in, so render/
never imports the spec. Errors a renderer finds in the scene are located with the plan's
:class:`~visualenv.source_map.SourceMap`, worded as the spec's loader words them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol, Union

from visualenv.files import MAX_IMAGE_PIXELS
from visualenv.physics.scene import PhysicsScene
from visualenv.source_map import SourceMap

#: 3 or 4 numbers in 0..1, linear
Color = tuple[float, ...]
Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class Texture:
    type: str  # noise, voronoi, checker, wave or image
    scale: float
    detail: float
    colors: tuple[Color, Color] | None
    image: str | tuple[str, ...] | None  # one file, or a set a binding chooses from


@dataclass(frozen=True, slots=True)
class Material:
    color: Color
    roughness: float
    metallic: float
    emission: Color | None
    emission_strength: float
    texture: Texture | None


@dataclass(frozen=True, slots=True)
class Craters:
    count: int
    radius: tuple[float, float]
    depth: float
    rim: float
    seed: int


@dataclass(frozen=True, slots=True)
class ObjectBase:
    location: Vec3
    rotation: Vec3
    scale: float | Vec3
    visible: bool
    parent: str | None


@dataclass(frozen=True, slots=True)
class PrimitiveObject(ObjectBase):
    primitive: str
    size: float | Vec3
    radius: float
    depth: float
    thickness: float
    segments: int
    craters: Craters | None
    label: str | None
    heightmap: str | None
    origin: str
    smooth: bool
    material: Material  # the spec's, else the default material


@dataclass(frozen=True, slots=True)
class MeshObject(ObjectBase):
    mesh: str
    material: Material | None  # None: the file's own
    label: str | None


@dataclass(frozen=True, slots=True)
class LightObject(ObjectBase):
    light: str
    strength: float
    color: Color
    spot_size: float
    size: float


@dataclass(frozen=True, slots=True)
class CameraObject(ObjectBase):
    camera: str
    lens: float
    sensor_width: float
    ortho_scale: float
    clip_start: float
    clip_end: float
    look_at: Vec3 | None


@dataclass(frozen=True, slots=True)
class EmptyObject(ObjectBase):
    pass


SceneObject = Union[PrimitiveObject, MeshObject, LightObject, CameraObject, EmptyObject]


@dataclass(frozen=True, slots=True)
class World:
    tint: Color  # the colour as given, else the spec's default for a plain background or an image
    strength: float
    image: str | None
    rotation: float | Vec3


@dataclass(frozen=True, slots=True)
class Scene:
    file: str | None
    file_scene: str | None
    objects: dict[str, SceneObject]
    world: World | None  # the spec's world; None: the file's, else `default_world`
    default_world: World
    default_material: Material  # for an object that a binding colours and that has no material of its own
    max_image_pixels: int = MAX_IMAGE_PIXELS  # the most pixels an image file may have, read from its header first


@dataclass(frozen=True, slots=True)
class Sensor:
    read_noise: float
    shot_noise: float
    gain: float
    gamma: float
    vignetting: float


@dataclass(frozen=True, slots=True)
class CameraView:
    camera: str
    resolution: tuple[int, int]  # width, height
    color: str  # rgb, grayscale, depth or segmentation
    depth_range: tuple[float, float]
    sensor: Sensor | None


@dataclass(frozen=True, slots=True)
class ViewSettings:
    camera: str | None
    resolution: tuple[int, int]
    preset: str


@dataclass(frozen=True, slots=True)
class RenderSettings:
    engine: str
    preset: str
    samples: int | None
    bounces: int | None
    device: str
    threads: int
    noise: str
    view: ViewSettings


@dataclass(frozen=True, slots=True)
class VideoBackground:
    """The Distracting Control Suite's backgrounds: DAVIS 2017's videos under `videos` (a folder, as resolved)."""

    videos: str
    split: str  # "train" or "val"


@dataclass(frozen=True, slots=True)
class Distractions:
    difficulty: float | tuple[float, float]  # a pair: each episode's drawn uniformly between them
    camera: bool
    colors: bool
    background: bool | VideoBackground  # True: visualenv's pattern; videos: the suite's
    dynamic: bool
    upper_hemisphere: bool | None = None  # None: limited unless the camera looks straight down
    floor_alpha: float | None = None  # None: the floor as it is

    @property
    def largest(self) -> float:
        """The largest difficulty an episode may draw (0: no distraction)."""
        return max(self.difficulty) if isinstance(self.difficulty, tuple) else self.difficulty


@dataclass(frozen=True, slots=True)
class BindingTarget:
    """One scene property a renderer sets before each render."""

    object: str
    property: str  # a key of visualenv.bindables.BINDABLES
    size: int  # how many values the binding function yields for it (1 for scalars)


class Overrides(Protocol):
    """What :meth:`RenderPlan.with_options` reads of a :class:`~visualenv.render.base.RendererOptions`."""

    def overrides(self) -> dict[str, Any]: ...


@dataclass(frozen=True, slots=True)
class RenderPlan:
    """Everything a renderer needs, produced by the compiler (``Program.render_plan()``)."""

    scene: Scene
    views: dict[str, CameraView]  # observation cameras by observation key
    single: bool  # one camera (Box) rather than several (Dict)
    settings: RenderSettings
    bindings: tuple[BindingTarget, ...]
    base_dir: Path
    source: SourceMap
    cameras: tuple[tuple[tuple[str | int, ...], str], ...] = ()  # every camera the spec names, with its field's path
    physics: PhysicsScene | None = None  # a physics spec's drawable model, posed from Frames.poses
    distractions: Distractions | None = None  # the distractions the env will ask for: a batch builds its scene for them

    def with_options(self, options: Overrides) -> RenderPlan:
        """This plan with the options' overrides written into its render settings (checked when the env made them)."""
        overrides = options.overrides()
        return replace(self, settings=replace(self.settings, **overrides)) if overrides else self

    @property
    def view_camera(self) -> str | None:
        """The camera of the human view: render.view.camera, else the first observation camera."""
        if self.settings.view.camera:
            return self.settings.view.camera
        return next(iter(self.views.values())).camera if self.views else None
