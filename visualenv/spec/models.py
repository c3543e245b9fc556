"""The spec file format, as pydantic models.

These models check shape, types and ranges; they know nothing of Blender or
Gymnasium. Expressions are kept as text (or plain numbers) here and checked by
:mod:`visualenv.expr` when the compiler resolves names. The JSON Schema in
``schemas/`` is generated from these classes (``visualenv schema``), so the
docstrings and ``Field`` descriptions are what editors show.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Optional, Union

from pydantic import ConfigDict, create_model, Field, ValidationInfo, field_validator, model_validator
from pydantic_core import PydanticCustomError

from visualenv.files import MAX_MODEL_MEMORY_MIB
from visualenv.spec.fields import BlenderName, ColorExpr, Expr, Name, StrictModel, Vec3Expr
from visualenv.bindables import BINDABLES
from visualenv.spec.scene_models import (  # noqa: F401 - the spec's parts, importable with the whole spec
    Texture,
    Material,
    ObjectBase,
    Craters,
    PrimitiveObject,
    MeshObject,
    LightObject,
    CameraObject,
    EmptyObject,
    SceneObject,
    World,
    Scene,
)
from visualenv.spec.view_models import (  # noqa: F401
    Sensor,
    ColorMode,
    CameraView,
    Observation,
    ViewSettings,
    RenderSettings,
    Distractions,
    VideoBackground,
)

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
    let: dict[Name, Expr] = Field(
        default_factory=dict, description="derived quantities, computed in order from the old state"
    )
    update: dict[Name, Expr] = Field(
        default_factory=dict,
        description="new state values (and, with physics, mocap poses mocap_<body>_...); all right-hand sides read the old state",
    )
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

    values: Annotated[dict[str, Expr], Field(min_length=1)] = Field(
        description=(
            "each try's values, as physics.reset.values (written, then the model forwarded); every try starts from the state "
            "physics.reset.values left"
        )
    )
    until: Expr = Field(
        description="a condition read after each try's forward, e.g. 'ncon == 0' (nothing touches): the first try that meets it is kept"
    )
    attempts: int = Field(
        1000, ge=1, le=1_000_000, description="tries at most; none meeting 'until' is a located fault at reset"
    )


class Search(StrictModel):
    """Values stepped until a condition holds, each try going on from the last (dm_control's quadruped raises its body
    1 cm at a time until nothing touches): a bounded loop on a value, where a redraw draws afresh."""

    until: Expr = Field(
        description="a condition read after each try's write and forward, e.g. 'ncon == 0': the first try that meets it is kept"
    )
    step: Annotated[dict[str, Expr], Field(min_length=1)] = Field(
        description=(
            "after a try that fails, the next try's values, from this try's (e.g. qpos_root_z: qpos_root_z + 0.01); the "
            "first try writes them as the values before it left them"
        )
    )
    attempts: int = Field(
        10_000, ge=1, le=1_000_000, description="tries at most; none meeting 'until' is a located fault at reset"
    )


class Settle(StrictModel):
    """Physics steps taken at reset, after the values are written (dm_control's cheetah settles 200 steps), with the controls the reset left (zero, or a keyframe's)."""

    steps: int = Field(
        ge=1, le=1_000_000, description="physics steps (the convention's step, in one call), before the episode's first"
    )
    time: float | None = Field(
        None,
        allow_inf_nan=False,
        description="the simulation time set after them (dm_control: 0); default: as they leave it",
    )


class PhysicsReset(StrictModel):
    """How each episode starts: MuJoCo's reset (or a keyframe), values written in order (random draws allowed), then
    optionally values drawn again (redraw) or stepped (search) until a condition holds and settling steps (settle):
    docs/physics.md#reset."""

    keyframe: str | None = Field(None, description="start from this named keyframe of the model instead of its qpos0")
    values: dict[str, Expr] = Field(
        default_factory=dict,
        description=(
            "evaluated in order after the reset: a key 'qpos_<joint>', 'qvel_<joint>', 'mocap_<body>_x' (_y, _z, _qw...) or a writable "
            "model field ('model_geom_pos_<geom>_x', 'model_dof_damping_<joint>') sets that value, 'qpos_a, qpos_b' sets "
            "several from a vector, any other name is a temporary later entries can read; an entry reads the model's reset values "
            "by the same names (e.g. qpos_hinge: qpos_hinge + uniform(-0.01, 0.01)); draws happen in this order"
        ),
    )
    redraw: Redraw | None = Field(None, description="values drawn again, after 'values', until a condition holds")
    search: Search | None = Field(
        None, description="values stepped, after 'values' and a redraw, until a condition holds (a bounded loop)"
    )
    settle: Settle | None = Field(None, description="physics steps taken last, e.g. {steps: 200, time: 0}")


class Physics(StrictModel):
    """MuJoCo physics: the MJCF model the env steps between the action and the reward (docs/physics.md)."""

    engine: Literal["mujoco"] = Field("mujoco", description="the physics engine")
    model: str = Field(
        description="the MJCF file, relative to the spec, or package:<package>/<path> for a file an installed package ships (found on disk; the package is not imported)"
    )
    frame_skip: int = Field(
        1, ge=1, le=100_000, description="physics steps per env step; dt in expressions is timestep * frame_skip"
    )
    convention: Literal["gymnasium", "dm_control"] = Field(
        "gymnasium",
        description=(
            "whose MuJoCo calls the env makes: Gymnasium's MujocoEnv (mj_step, then mj_rnePostConstraint; draws from np_random) or "
            "dm_control's Physics (its legacy step ending in mj_step1, forwards with actuation disabled at reset; draws from "
            "RandomState(seed), continued across episodes), so the library's env is reproduced to the bit (docs/dmc.md)"
        ),
    )
    reset: PhysicsReset = Field(default_factory=PhysicsReset)
    contacts: dict[Name, Annotated[list[str], Field(min_length=2, max_length=2)]] = Field(
        default_factory=dict, description="name: [geom, geom]: a condition, true while the two geoms touch"
    )
    observe: Annotated[list[Expr], Field(min_length=1)] | None = Field(
        None,
        description="the state-only observation (float64), one number per entry; default: every qpos, then every qvel, then the observed state",
    )
    draw_sites: bool = Field(
        True,
        description="draw the model's sites as MuJoCo's viewer does (groups 0 to 2, their rgba and size); false: not drawn",
    )
    max_memory_mib: int = Field(
        MAX_MODEL_MEMORY_MIB,
        ge=1,
        description=(
            "the most memory (MiB) compiling the model may take, estimated from the MJCF and its files' headers "
            "(height fields, textures, <size memory>) before MuJoCo is asked to: raise it for a larger model you trust"
        ),
    )
    look: Literal["mujoco", "physical"] = Field(
        "mujoco",
        description=(
            "how the model is lit and coloured: 'mujoco' as MuJoCo's renderer draws it (its headlight and lights, their ambient and "
            "diffuse terms, shadows, colours written without a display transform), evenly lit at 1 sample; 'physical': Blender's "
            "path-traced light (the model's lights, or a sun standing in for the headlight, the world's light, sRGB colours)"
        ),
    )


# -- actors, observation, rendering --------------------------------------------------------------


#: the type of a binding's value in the file, by the value kind of :mod:`bindables`
_BINDING_TYPES: dict[str, Any] = {
    "vector": Vec3Expr,
    "scale": Union[Vec3Expr, Expr],
    "color": ColorExpr,
    "number": Expr,
    "condition": Expr,
}

#: Properties of a scene object recomputed from state before every render: one optional field per entry of ``BINDABLES``.
Actor = create_model(
    "Actor",
    __base__=StrictModel,
    __module__=__name__,
    __doc__="Properties of a scene object recomputed from state before every render.",
    **{b.name: (Optional[_BINDING_TYPES[b.value]], Field(None, description=b.description)) for b in BINDABLES.values()},  # type: ignore[call-overload]
)


# -- the whole spec ---------------------------------------------------------------------------------


class Spec(StrictModel):
    """A visualenv environment: scene, state, dynamics, actions, rewards and observation."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, strict=True, json_schema_extra={"$id": "https://visualenv.dev/schema/spec.json"}
    )

    id: str = Field(pattern=r"^[A-Za-z][A-Za-z0-9_.-]*-v\d+$", description="environment id, e.g. VisualCartPole-v0")
    description: str = ""
    scene: Scene = Field(default_factory=Scene)
    params: dict[Name, Union[bool, int, float, str]] = Field(
        default_factory=dict, description="named constants; a value may be an expression over earlier params"
    )
    physics: Physics | None = Field(None, description="MuJoCo physics stepped between the action and the reward")
    # both default to None only to tell "not given" apart: _state_given and _actions_given turn it into {} or an error
    state: dict[Name, StateVar] = Field(
        None, validate_default=True, description="state variables, in observation order (at least one without physics)"
    )
    actions: Actions | None = Field(
        None,
        validate_default=True,
        description="required without physics; with it, default: one Box dimension per actuator (its ctrlrange)",
    )
    dynamics: Dynamics = Field(default_factory=Dynamics)
    # Actor is made from BINDABLES
    actors: dict[BlenderName, Actor] = Field(default_factory=dict, description="scene objects bound to expressions")
    observation: Observation | None = Field(None, description="camera observation; without it the env is state-only")
    render: RenderSettings = Field(default_factory=RenderSettings)
    reward: Expr = Field(0.0, description="reward every step (outcome rewards are added)")
    outcomes: dict[Name, Outcome] = Field(
        default_factory=dict, description="named rules checked in order; the first ending one ends the episode"
    )
    max_steps: int = Field(1000, ge=1, le=100_000_000, description="episodes are truncated after this many steps")
    action_repeat: int = Field(
        1,
        ge=1,
        le=10_000,
        description=(
            "steps the spec makes per env.step() with the same action (dm_control's action repeat): their rewards summed, one "
            "observation; max_steps, steps and dt count the spec's own steps; make(action_repeat=k) overrides it"
        ),
    )
    distractions: Optional[Distractions] = Field(
        None,
        description=(
            "changes of the observation's camera and colours per episode, the state and rewards untouched; make(distractions=...) overrides it"
        ),
    )
    dt: float = Field(1.0, gt=0, description="seconds per step, available as 'dt' in expressions")
    on_fault: Literal["raise", "terminate"] = Field(
        "raise",
        description="a NaN/inf state or math error in a step: raise StepError, or end the episode with info['error']",
    )

    @field_validator("state", mode="before")
    @classmethod
    def _state_given(cls, value: Any, info: ValidationInfo) -> Any:
        """State is required and not empty, except beside physics (whose state is the model's)."""
        # physics given (or given and invalid: reported there)
        if info.data.get("physics") is not None or "physics" not in info.data:
            return {} if value is None else value
        if value is None:
            raise PydanticCustomError("missing", "Field required")
        if isinstance(value, dict) and not value:
            raise PydanticCustomError(
                "too_short", "at least 1 entry", {"field_type": "Dictionary", "min_length": 1, "actual_length": 0}
            )
        return value

    @field_validator("actions", mode="before")
    @classmethod
    def _actions_given(cls, value: Any, info: ValidationInfo) -> Any:
        """Actions are required, except beside physics (default: one Box dimension per actuator)."""
        if value is None and "physics" in info.data and info.data["physics"] is None:
            raise PydanticCustomError("missing", "Field required")
        return value

    @property
    def declares_success(self) -> bool:
        """Whether an outcome (or milestone) marks a success: else ``info["is_success"]`` is always False, and a success
        rate says nothing (DMC tasks declare none)."""
        return any(outcome.success for outcome in self.outcomes.values())

    def camera_uses(self) -> list[tuple[tuple, str]]:
        """Every camera the spec names, with the path of the field that names it (for errors located in the file)."""
        uses: list[tuple[tuple, str]] = []
        if self.observation is not None:
            single = self.observation.cameras is None
            uses += [
                (("observation", "camera") if single else ("observation", "cameras", key, "camera"), view.camera)
                for key, view in self.observation.views().items()
            ]
        if self.render.view.camera:
            uses.append((("render", "view", "camera"), self.render.view.camera))
        return uses
