"""The spec file format, as pydantic models.

These models check shape, types and ranges; they know nothing of Blender or
Gymnasium. Expressions are kept as text (or plain numbers) here and checked by
:mod:`visualenv.expr` when the compiler resolves names. The JSON Schema in
``schemas/`` is generated from these classes (``visualenv schema``), so the
docstrings and ``Field`` descriptions are what editors show.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Optional, Union

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, ValidationInfo, create_model, field_validator, model_validator
from pydantic_core import PydanticCustomError

from visualenv.bindables import BINDABLES

#: An expression: a number, a boolean or the text of an expression such as ``"x + tau * x_dot"``.
Expr = Annotated[Union[bool, int, float, str], Field(description="a number or an expression")]
#: A 3-vector: a list of three expressions, or one expression text such as ``"[x, 0, 0]"``.
Vec3Expr = Annotated[Union[Annotated[list[Expr], Field(min_length=3, max_length=3)], str], Field(description="three expressions, or one vector expression")]
#: A colour: three (RGB) or four (RGBA) expressions in 0..1, or one vector expression.
ColorExpr = Annotated[Union[Annotated[list[Expr], Field(min_length=3, max_length=4)], str], Field(description="RGB or RGBA in 0..1 (on a material, alpha below 1 is see-through)")]

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Color = Annotated[list[Annotated[float, Field(ge=0.0)]], Field(min_length=3, max_length=4, description="RGB or RGBA, linear, 0..1")]
Name = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", description="an identifier")]
#: A name as Blender writes it (objects, cameras, scenes): dots, spaces and non-ASCII letters included, as in 'Cube.001'
BlenderName = Annotated[str, Field(pattern=r"^[^\x00-\x1f\x7f]+$", max_length=255, description="a Blender name, e.g. 'Cube.001' (any text without control characters)")]
Resolution = Annotated[list[Annotated[int, Field(ge=4, le=8192)]], Field(min_length=2, max_length=2, description="[width, height] in pixels (Blender renders at least 4)")]


class StrictModel(BaseModel):
    """Unknown keys are errors and types are strict: a misspelt key or a quoted number must not be silently accepted.

    Strict mode refuses ``"10"`` for an integer, ``true`` for a number and ``"yes"``
    for a boolean (an integer is still accepted where a number is expected).
    """

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


# -- scene ------------------------------------------------------------------------------------


class Texture(StrictModel):
    """A procedural or image texture that drives the base colour of a material."""

    type: Literal["noise", "voronoi", "checker", "wave", "image"] = Field(description="texture kind")
    scale: float = Field(5.0, gt=0, description="texture coordinate scale (procedural kinds)")
    detail: float = Field(2.0, ge=0, le=15, description="noise detail")
    colors: Annotated[list[Color], Field(min_length=2, max_length=2)] | None = Field(None, description="two colours the texture value blends between (procedural kinds)")
    image: Union[str, Annotated[list[str], Field(min_length=1)], None] = Field(
        None, description="image file, relative to the spec (type: image); or a list of files, a texture set an actor's 'texture' picks from")

    @model_validator(mode="after")
    def _image_needs_file(self) -> "Texture":
        if self.type == "image" and not self.image:
            raise ValueError("an image texture needs 'image': a file path")
        return self


class Material(StrictModel):
    """A Principled BSDF material."""

    color: Color = Field([0.8, 0.8, 0.8], description="base colour; an alpha below 1 makes the surface see-through")
    roughness: float = Field(0.5, ge=0, le=1)
    metallic: float = Field(0.0, ge=0, le=1)
    emission: Color | None = Field(None, description="emission colour")
    emission_strength: float = Field(1.0, ge=0)
    texture: Texture | None = None


class ObjectBase(StrictModel):
    location: Vec3 = Field([0.0, 0.0, 0.0], description="initial location (m)")
    rotation: Vec3 = Field([0.0, 0.0, 0.0], description="initial Euler XYZ rotation (radians)")
    scale: Union[float, Vec3] = Field(1.0, description="initial scale")
    visible: bool = True
    parent: BlenderName | None = Field(None, description="name of the parent object")


class Craters(StrictModel):
    """Bowl-shaped craters pressed into a terrain: real geometry, so a low sun casts shadows in them.

    Each crater of radius R is a parabolic bowl ``depth * 2R`` deep with a raised
    rim ``rim * 2R`` high whose ejecta fall off as ``(R / r)**3`` outside it (the
    usual profile of a simple crater); craters add up where they overlap. Radii
    are drawn log-uniformly (small craters are the common ones), places uniformly,
    from ``seed``: the same spec always builds the same ground.
    """

    count: int = Field(40, ge=1, le=2000, description="number of craters")
    radius: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=2, max_length=2)] = Field([0.5, 5.0], description="[smallest, largest] crater radius (m)")
    depth: float = Field(0.2, ge=0, le=1, description="bowl depth as a fraction of the diameter")
    rim: float = Field(0.04, ge=0, le=1, description="rim height as a fraction of the diameter")
    seed: int = Field(0, ge=0, description="seed of the crater places and sizes")

    @field_validator("radius")
    @classmethod
    def _radius_order(cls, radius: list[float]) -> list[float]:
        if radius[0] > radius[1]:
            raise ValueError("[smallest, largest]: the first must not be greater")
        return radius


class PrimitiveObject(ObjectBase):
    """A mesh primitive built by the compiler."""

    primitive: Literal["cube", "plane", "sphere", "cylinder", "cone", "torus", "disk", "ring", "terrain"]
    size: Union[Annotated[float, Field(gt=0)], Vec3] = Field(1.0, description="cube/plane/terrain edge length, or [x, y, z] dimensions")
    radius: float = Field(0.5, gt=0, description="sphere/cylinder/cone/disk/torus radius")
    depth: float = Field(1.0, gt=0, description="cylinder/cone height")
    thickness: float = Field(0.05, gt=0, description="ring/torus tube thickness")
    segments: int = Field(32, ge=3, le=512, description="round primitives: segments around; terrain: grid cells along each side")
    craters: Craters | None = Field(None, description="terrain: craters pressed into the ground")
    label: Name | None = Field(None, description="segmentation: objects that share a label share an id (default: the object's own name)")
    heightmap: str | None = Field(None, description="terrain: elevation data, relative to the spec: a grayscale PNG (8 or 16 bit), TIFF or .npy; "
                                  "size [x, y, z] spans it, the lowest value at 0 and the highest at z")
    origin: Literal["center", "bottom"] = Field("center", description="where the object's origin sits")
    smooth: bool = False
    material: Material | None = None

    @model_validator(mode="after")
    def _heightmap_needs_a_height(self) -> "PrimitiveObject":
        if self.heightmap is not None and self.primitive == "terrain" and not isinstance(self.size, list):
            raise ValueError("a terrain with a heightmap needs size: [x, y, z] (z: the height of the map's highest value)")
        return self


class MeshObject(ObjectBase):
    """A mesh imported from a file (.obj, .stl, .ply, .glb/.gltf)."""

    mesh: str = Field(description="mesh file, relative to the spec")
    material: Material | None = None
    label: Name | None = Field(None, description="segmentation: objects that share a label share an id (default: the object's own name)")


class LightObject(ObjectBase):
    light: Literal["sun", "point", "spot", "area"]
    strength: float = Field(3.0, ge=0, description="sun: irradiance (W/m2); others: power (W)")
    color: Color = [1.0, 1.0, 1.0]
    spot_size: float = Field(0.785, gt=0, le=3.1416, description="spot cone angle (radians)")
    size: float = Field(0.25, ge=0, description="light radius or area size (m)")


class CameraObject(ObjectBase):
    camera: Literal["perspective", "orthographic"]
    lens: float = Field(35.0, gt=0, description="focal length (mm)")
    sensor_width: float = Field(36.0, gt=0, description="sensor width (mm)")
    ortho_scale: float = Field(6.0, gt=0, description="view width for orthographic cameras (m)")
    clip_start: float = Field(0.05, gt=0)
    clip_end: float = Field(200.0, gt=0)
    look_at: Vec3 | None = Field(None, description="point the camera at this location (overrides rotation)")

    @model_validator(mode="after")
    def _clip_order(self) -> "CameraObject":
        if self.clip_end <= self.clip_start:
            raise ValueError("clip_end must be greater than clip_start")
        return self


class EmptyObject(ObjectBase):
    """An empty: a transform other objects can be parented to."""

    empty: Literal[True] = True


def _object_kind(value: Any) -> str | None:
    if isinstance(value, dict):
        for kind in ("primitive", "mesh", "light", "camera", "empty"):
            if kind in value:
                return kind
        return None
    fields = getattr(type(value), "model_fields", {})
    return next((kind for kind in ("primitive", "mesh", "light", "camera", "empty") if kind in fields), None)


SceneObject = Annotated[
    Union[
        Annotated[PrimitiveObject, Tag("primitive")],
        Annotated[MeshObject, Tag("mesh")],
        Annotated[LightObject, Tag("light")],
        Annotated[CameraObject, Tag("camera")],
        Annotated[EmptyObject, Tag("empty")],
    ],
    Discriminator(
        _object_kind,
        custom_error_type="object_kind",
        custom_error_message="an object needs one of 'primitive', 'mesh', 'light', 'camera' or 'empty'",
    ),
]


class World(StrictModel):
    """The background: a colour, or an environment image that lights the scene and shows behind it.

    Bind ``strength``, ``rotation`` or ``color`` (a tint of the image) through an actor named ``World``.
    """

    color: Color | None = Field(None, description="background colour (default dark grey); with an image, a tint that multiplies it (default white)")
    strength: float = Field(1.0, ge=0)
    image: str | None = Field(None, description="an environment map (equirectangular: .hdr, .exr, .png, .jpg, any image Blender reads), "
                              "relative to the spec: it lights the scene and shows behind it")
    rotation: Union[float, Vec3] = Field(0.0, description="turns the image: radians about the vertical axis, or Euler XYZ [x, y, z]")

    def tint(self) -> list[float]:
        """The colour as given, else dark grey (a plain background) or white (an image shown as it is)."""
        if self.color is not None:
            return list(self.color)
        return [1.0, 1.0, 1.0] if self.image is not None else [0.05, 0.05, 0.05]


class Scene(StrictModel):
    """The Blender scene: a .blend file, declared objects, or both."""

    file: str | None = Field(None, description="a .blend file made in Blender, relative to the spec; its objects are bound by name")
    file_scene: BlenderName | None = Field(None, description="which scene of the .blend to use; needed when the file has more than one")
    objects: dict[BlenderName, SceneObject] = Field(default_factory=dict, description="objects to build (added to the file's scene, if any)")
    world: World | None = Field(None, description="background; default: the file's world, or dark grey")

    @model_validator(mode="after")
    def _file_scene_needs_a_file(self) -> "Scene":
        if self.file_scene is not None and self.file is None:
            raise ValueError("file_scene names a scene of the .blend in 'file', and there is no file")
        return self


# -- state, actions, dynamics -------------------------------------------------------------------


class StateVar(StrictModel):
    init: Expr = Field(description="initial value at reset; may draw random numbers, e.g. uniform(-0.05, 0.05)")
    observe: bool = Field(True, description="part of the state-only observation vector")


class ContinuousInput(StrictModel):
    low: float
    high: float

    @model_validator(mode="after")
    def _order(self) -> "ContinuousInput":
        if self.high <= self.low:
            raise ValueError("high must be greater than low")
        return self


class Actions(StrictModel):
    """Either discrete actions (each sets per-step inputs) or continuous inputs (a Box)."""

    discrete: Annotated[list[dict[Name, Expr]], Field(min_length=1)] | None = Field(
        None, description="action i sets these inputs for the step; inputs an action omits are 0"
    )
    continuous: Annotated[dict[Name, ContinuousInput], Field(min_length=1)] | None = Field(
        None, description="one Box dimension per input, in this order, clipped to [low, high]"
    )

    @model_validator(mode="after")
    def _exactly_one(self) -> "Actions":
        if (self.discrete is None) == (self.continuous is None):
            raise ValueError("give exactly one of 'discrete' or 'continuous'")
        return self


class Dynamics(StrictModel):
    let: dict[Name, Expr] = Field(default_factory=dict, description="derived quantities, computed in order from the old state")
    update: dict[Name, Expr] = Field(default_factory=dict, description="new state values (and, with physics, mocap poses mocap_<body>_...); all right-hand sides read the old state")
    python: str | None = Field(
        None,
        pattern=r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$",
        description="escape hatch, RUNS USER CODE: 'module:function' called as f(state, inputs, params, rng) -> dict of new state values",
    )


class Outcome(StrictModel):
    when: Expr = Field(description="condition, checked after each update")
    reward: Expr = Field(0.0, description="added to the step's reward when the outcome fires")
    end: Literal["terminate", "truncate", "none"] = Field(
        "terminate", description="terminate or truncate the episode; 'none' marks a milestone that fires once"
    )
    success: bool = Field(False, description="the episode counts as a success (info['is_success'])")


# -- physics ----------------------------------------------------------------------------------------


class Redraw(StrictModel):
    """Values drawn again until a condition holds (dm_control's rejection loops: joints redrawn until nothing touches)."""

    values: Annotated[dict[str, Expr], Field(min_length=1)] = Field(description=(
        "each try's values, as physics.reset.values (written, then the model forwarded); every try starts from the state "
        "physics.reset.values left"))
    until: Expr = Field(description="a condition read after each try's forward, e.g. 'ncon == 0' (nothing touches): the first try that meets it is kept")
    attempts: int = Field(1000, ge=1, le=1_000_000, description="tries at most; none meeting 'until' is a located fault at reset")


class Settle(StrictModel):
    """Physics steps taken at reset, after the values are written (dm_control's cheetah settles 200 steps), with the controls the reset left (zero, or a keyframe's)."""

    steps: int = Field(ge=1, le=1_000_000, description="physics steps (the convention's step, in one call), before the episode's first")
    time: float | None = Field(None, allow_inf_nan=False, description="the simulation time set after them (dm_control: 0); default: as they leave it")


class PhysicsReset(StrictModel):
    """How each episode starts: MuJoCo's reset (or a keyframe), values written in order (random draws allowed), then
    optionally values drawn again until a condition holds (redraw) and settling steps (settle): docs/physics.md#reset."""

    keyframe: str | None = Field(None, description="start from this named keyframe of the model instead of its qpos0")
    values: dict[str, Expr] = Field(default_factory=dict, description=(
        "evaluated in order after the reset: a key 'qpos_<joint>', 'qvel_<joint>', 'mocap_<body>_x' (_y, _z, _qw...) or a writable "
        "model field ('model_geom_pos_<geom>_x', 'model_dof_damping_<joint>') sets that value, 'qpos_a, qpos_b' sets "
        "several from a vector, any other name is a temporary later entries can read; an entry reads the model's reset values "
        "by the same names (e.g. qpos_hinge: qpos_hinge + uniform(-0.01, 0.01)); draws happen in this order"))
    redraw: Redraw | None = Field(None, description="values drawn again, after 'values', until a condition holds")
    settle: Settle | None = Field(None, description="physics steps taken last, e.g. {steps: 200, time: 0}")


class Physics(StrictModel):
    """MuJoCo physics: the MJCF model the env steps between the action and the reward (docs/physics.md)."""

    engine: Literal["mujoco"] = Field("mujoco", description="the physics engine")
    model: str = Field(description="the MJCF file, relative to the spec, or package:<package>/<path> for a file an installed package ships (found on disk; the package is not imported)")
    frame_skip: int = Field(1, ge=1, le=100_000, description="physics steps per env step; dt in expressions is timestep * frame_skip")
    convention: Literal["gymnasium", "dm_control"] = Field("gymnasium", description=(
        "whose MuJoCo calls the env makes: Gymnasium's MujocoEnv (mj_step, then mj_rnePostConstraint; draws from np_random) or "
        "dm_control's Physics (its legacy step ending in mj_step1, forwards with actuation disabled at reset; draws from "
        "RandomState(seed), continued across episodes), so the library's env is reproduced to the bit (docs/dmc.md)"))
    reset: PhysicsReset = Field(default_factory=PhysicsReset)
    contacts: dict[Name, Annotated[list[str], Field(min_length=2, max_length=2)]] = Field(
        default_factory=dict, description="name: [geom, geom]: a condition, true while the two geoms touch")
    observe: Annotated[list[Expr], Field(min_length=1)] | None = Field(
        None, description="the state-only observation (float64), one number per entry; default: every qpos, then every qvel, then the observed state")
    draw_sites: bool = Field(True, description="draw the model's sites as MuJoCo's viewer does (groups 0 to 2, their rgba and size); false: not drawn")
    look: Literal["mujoco", "physical"] = Field("mujoco", description=(
        "how the model is lit and coloured: 'mujoco' as MuJoCo's renderer draws it (its headlight and lights, their ambient and "
        "diffuse terms, shadows, colours written without a display transform), evenly lit at 1 sample; 'physical': Blender's "
        "path-traced light (the model's lights, or a sun standing in for the headlight, the world's light, sRGB colours)"))


# -- actors, observation, rendering --------------------------------------------------------------


#: the type of a binding's value in the file, by the value kind of :mod:`bindables`
_BINDING_TYPES: dict[str, Any] = {"vector": Vec3Expr, "scale": Union[Vec3Expr, Expr], "color": ColorExpr, "number": Expr, "condition": Expr}

#: Properties of a scene object recomputed from state before every render: one optional field per entry of ``BINDABLES``.
Actor = create_model(
    "Actor", __base__=StrictModel, __module__=__name__, __doc__="Properties of a scene object recomputed from state before every render.",
    **{b.name: (Optional[_BINDING_TYPES[b.value]], Field(None, description=b.description)) for b in BINDABLES.values()},  # type: ignore[call-overload]
)


class Sensor(StrictModel):
    """A camera sensor's imperfections, applied in numpy to each observation after readback.

    With v a pixel as a fraction of full scale (its byte / 255): ``v *= 1 - vignetting * r**2``
    (r: distance from the centre, 1 at the corners), then photon noise of std
    ``shot_noise * sqrt(v)`` and read noise of std ``read_noise``, then ``v *= gain``,
    clipped to 0..1, ``v **= gamma``, rounded to a byte. Noise is drawn from the env's
    seeded generator: the same seed gives the same frames.
    """

    read_noise: float = Field(0.0, ge=0, le=1, description="std of Gaussian noise, as a fraction of full scale")
    shot_noise: float = Field(0.0, ge=0, le=1, description="photon noise: std shot_noise * sqrt(v) at intensity v (fraction of full scale)")
    gain: float = Field(1.0, gt=0, le=100, description="exposure: intensities multiplied by this")
    gamma: float = Field(1.0, gt=0, le=10, description="response curve v ** gamma (below 1 brightens the shadows)")
    vignetting: float = Field(0.0, ge=0, le=1, description="darkening at the corners: the fraction of light lost there (falls off as r squared)")


def _sensor_on_light(color: str, sensor: "Sensor | None") -> None:
    if sensor is not None and color not in ("rgb", "grayscale"):
        raise ValueError(f"a sensor model acts on light: it needs color 'rgb' or 'grayscale', not '{color}'")


#: what an observation camera gives: light (rgb, grayscale), distance (depth) or object ids (segmentation)
ColorMode = Literal["rgb", "grayscale", "depth", "segmentation"]


class CameraView(StrictModel):
    camera: BlenderName = Field(description="a camera in the scene")
    resolution: Resolution = Field([100, 100], description="[width, height]")
    color: ColorMode = "grayscale"
    depth_range: Annotated[list[Annotated[float, Field(ge=0)]], Field(min_length=2, max_length=2)] = Field(
        [0.0, 20.0], description="depth observations: distances mapped to 0..255"
    )
    sensor: Sensor | None = Field(None, description="camera imperfections (noise, gain, gamma, vignetting) on this camera's frames")

    @model_validator(mode="after")
    def _sensor_needs_light(self) -> "CameraView":
        _sensor_on_light(self.color, self.sensor)
        return self

    @field_validator("resolution")
    @classmethod
    def _pixels(cls, value: list[int]) -> list[int]:
        if value[0] * value[1] > 16_777_216:
            raise ValueError("resolution is too large (at most 16 megapixels)")
        return value


class Observation(StrictModel):
    """What the agent sees: one camera (a Box) or several (a Dict)."""

    camera: BlenderName | None = Field(None, description="the single observation camera")
    resolution: Resolution = Field([100, 100], description="[width, height]")
    color: ColorMode = "grayscale"
    depth_range: Annotated[list[Annotated[float, Field(ge=0)]], Field(min_length=2, max_length=2)] = [0.0, 20.0]
    sensor: Sensor | None = Field(None, description="camera imperfections (noise, gain, gamma, vignetting) on the single camera's frames")
    cameras: Annotated[dict[Name, CameraView], Field(min_length=1)] | None = Field(None, description="several cameras: a Dict observation keyed by these names")

    @field_validator("resolution")
    @classmethod
    def _pixels(cls, value: list[int]) -> list[int]:
        return CameraView._pixels(value)

    @model_validator(mode="after")
    def _one_or_many(self) -> "Observation":
        if (self.camera is None) == (self.cameras is None):
            raise ValueError("give either 'camera' (one camera) or 'cameras' (several)")
        if self.cameras is not None and self.sensor is not None:
            raise ValueError("with several 'cameras', give each camera its own 'sensor'")
        _sensor_on_light(self.color, self.sensor)
        return self

    def views(self) -> dict[str, CameraView]:
        """Every observation camera by key (the single camera's key is its name)."""
        if self.cameras is not None:
            return dict(self.cameras)
        assert self.camera is not None
        return {self.camera: CameraView(camera=self.camera, resolution=self.resolution, color=self.color, depth_range=self.depth_range, sensor=self.sensor)}


class ViewSettings(StrictModel):
    """The human view returned by ``env.render()`` (render_mode='rgb_array')."""

    camera: BlenderName | None = Field(None, description="default: the (first) observation camera")
    resolution: Resolution = [400, 400]
    preset: Literal["fast", "quality"] = "quality"

    @field_validator("resolution")
    @classmethod
    def _pixels(cls, value: list[int]) -> list[int]:
        return CameraView._pixels(value)


class RenderSettings(StrictModel):
    """The spec's ``render`` section: engine, quality preset, device and threads of every render, and the human view."""

    engine: Literal["cycles", "workbench", "eevee"] = "cycles"
    preset: Literal["fast", "quality"] = Field("fast", description="fast: 1 sample, no bounces (training); quality: previews")
    samples: int | None = Field(None, ge=1, le=4096, description="overrides the preset's samples")
    bounces: int | None = Field(None, ge=0, le=128, description="overrides the preset's light bounces")
    device: Literal["cpu", "gpu", "auto"] = Field("cpu", description="Cycles device; gpu falls back to cpu with a message")
    threads: int = Field(0, ge=0, le=256, description="render threads, 0: all cores")
    noise: Literal["independent", "shared"] = Field(
        "independent", description="Cycles' sampling noise: independent per pixel (Cycles' default), or shared by every pixel "
        "(scrambling distance 0: a pixel's value does not depend on where it lies in the image; batched envs render so)")
    view: ViewSettings = Field(default_factory=ViewSettings)


class Distractions(StrictModel):
    """The ``distractions`` section: what the observation shows changed per episode (or drifting every step), the
    state and rewards untouched; the Distracting Control Suite's kinds at its scale (docs/distractions.md)."""

    difficulty: float = Field(ge=0.0, le=1.0, description=(
        "the scale of every change: camera orbit and roll up to difficulty x pi/2, zoom up to difficulty/2, colours "
        "shifted by up to difficulty per channel (the Distracting Control Suite's 0.1, 0.2, 0.3)"))
    camera: bool = Field(True, description="the observation cameras orbit, roll and zoom about the point they look at")
    colors: bool = Field(True, description="every material's colour and the sky's shift")
    background: bool = Field(True, description=(
        "a moving pattern of two random colours in place of the sky, seen by the camera only (standing in for the suite's videos)"))
    dynamic: bool = Field(False, description="false: drawn at reset and kept for the episode; true: drifting every step as well")


# -- the whole spec ---------------------------------------------------------------------------------


class Spec(StrictModel):
    """A visualenv environment: scene, state, dynamics, actions, rewards and observation."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, json_schema_extra={"$id": "https://visualenv.dev/schema/spec.json"})

    id: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_.-]*-v\d+$", description="environment id, e.g. VisualCartPole-v0")
    description: str = ""
    scene: Scene = Field(default_factory=Scene)
    params: dict[Name, Union[bool, int, float, str]] = Field(
        default_factory=dict, description="named constants; a value may be an expression over earlier params"
    )
    physics: Physics | None = Field(None, description="MuJoCo physics stepped between the action and the reward")
    # both default to None only to tell "not given" apart: _state_given and _actions_given turn it into {} or an error
    state: dict[Name, StateVar] = Field(None, validate_default=True, description="state variables, in observation order (at least one without physics)")  # type: ignore[assignment]
    actions: Actions | None = Field(None, validate_default=True, description="required without physics; with it, default: one Box dimension per actuator (its ctrlrange)")
    dynamics: Dynamics = Field(default_factory=Dynamics)
    actors: dict[BlenderName, Actor] = Field(default_factory=dict, description="scene objects bound to expressions")  # type: ignore[valid-type]  # Actor is made from BINDABLES
    observation: Observation | None = Field(None, description="camera observation; without it the env is state-only")
    render: RenderSettings = Field(default_factory=RenderSettings)
    reward: Expr = Field(0.0, description="reward every step (outcome rewards are added)")
    outcomes: dict[Name, Outcome] = Field(default_factory=dict, description="named rules checked in order; the first ending one ends the episode")
    max_steps: int = Field(1000, ge=1, le=100_000_000, description="episodes are truncated after this many steps")
    action_repeat: int = Field(1, ge=1, le=10_000, description=(
        "steps the spec makes per env.step() with the same action (dm_control's action repeat): their rewards summed, one "
        "observation; max_steps, steps and dt count the spec's own steps; make(action_repeat=k) overrides it"))
    distractions: Optional[Distractions] = Field(None, description=(
        "changes of the observation's camera and colours per episode, the state and rewards untouched; make(distractions=...) overrides it"))
    dt: float = Field(1.0, gt=0, description="seconds per step, available as 'dt' in expressions")
    on_fault: Literal["raise", "terminate"] = Field(
        "raise", description="a NaN/inf state or math error in a step: raise StepError, or end the episode with info['error']"
    )

    @field_validator("state", mode="before")
    @classmethod
    def _state_given(cls, value: Any, info: ValidationInfo) -> Any:
        """State is required and not empty, except beside physics (whose state is the model's)."""
        if info.data.get("physics") is not None or "physics" not in info.data:  # physics given (or given and invalid: reported there)
            return {} if value is None else value
        if value is None:
            raise PydanticCustomError("missing", "Field required")
        if isinstance(value, dict) and not value:
            raise PydanticCustomError("too_short", "at least 1 entry", {"field_type": "Dictionary", "min_length": 1, "actual_length": 0})
        return value

    @field_validator("actions", mode="before")
    @classmethod
    def _actions_given(cls, value: Any, info: ValidationInfo) -> Any:
        """Actions are required, except beside physics (default: one Box dimension per actuator)."""
        if value is None and "physics" in info.data and info.data["physics"] is None:
            raise PydanticCustomError("missing", "Field required")
        return value

    def camera_uses(self) -> list[tuple[tuple, str]]:
        """Every camera the spec names, with the path of the field that names it (for errors located in the file)."""
        uses: list[tuple[tuple, str]] = []
        if self.observation is not None:
            single = self.observation.cameras is None
            uses += [(("observation", "camera") if single else ("observation", "cameras", key, "camera"), view.camera)
                     for key, view in self.observation.views().items()]
        if self.render.view.camera:
            uses.append((("render", "view", "camera"), self.render.view.camera))
        return uses
