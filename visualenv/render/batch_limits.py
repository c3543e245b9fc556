"""What a batch (many envs in one Blender scene) cannot render, found from the plan alone, before Blender starts.

A batch renders every env through one custom camera with one world; a bound sun
is copied per env and lights only its own copy (Cycles' light linking, at most
:data:`MAX_LINKED_ENVS` envs). A camera the state turns (a bound rotation, a
``look_at``, an aimed camera that moves; a MuJoCo model's camera on a moving body or
aimed at one; an observation camera a distraction orbits) is followed by turning each env's rays in the
camera's shader, up to :data:`MAX_TURNING_ENVS` envs (a model camera that only moves, ``track`` or
``trackcom``, is followed by moving each env's copy, at any number of envs). So an engine other
than Cycles, a bound world, a bound sun past that many envs or under a world that is not one colour, a camera the state
zooms (``lens``) or scales, a turning camera past its envs or with a depth
observation are refused when the batch is built (``BatchedVectorEnv(...)``),
not at its first render. Objects of a .blend file (their types, parents,
constraints) are only known to Blender: the renderer checks those again when it
builds the scene, with the same messages (:mod:`visualenv.render.blender.batch.renderer`).
"""

from __future__ import annotations

from visualenv.errors import SpecError
from visualenv.render.base import RenderPlan
from visualenv.bindables import WORLD_ACTOR
from visualenv.render.plan import CameraObject, LightObject

#: properties that turn a camera (bound on it or on an ancestor): a batch follows them by turning each env's rays
TURNS = ("rotation", "look_at")
#: properties a batch cannot follow: a scale bound on a camera or an ancestor, and the camera's own lens
UNFOLLOWED = ("scale",)
#: envs of a batch whose camera turns: its tiles shader holds 4 parameters an env (a quaternion) and Cycles compiles it
#: again whenever a rotation changes, at a cost that grows with N (results/benchmarks/batched-suns-and-cameras.md);
#: more were not tried
MAX_TURNING_ENVS = 1024
#: envs with lights of their own (a bound sun; point, spot and area lights) in one batch: Cycles' light linking tells
#: 64 light sets apart, one of them the default set: with suns, 63 envs' tiles equal their own renders, at 64 every
#: tile is wrong (results/benchmarks/batched-suns-and-cameras.md)
MAX_LINKED_ENVS = 63
ONE_PROCESS_EACH = "use one process per env (visualenv.make_vec(..., batched=False))"


def engine_message(engine: str) -> str:
    return (
        f"render.engine '{engine}' cannot render a batch in one call: only Cycles can (through its custom camera); "
        "use engine: cycles, or one process per env (visualenv.make_vec(..., batched=False))"
    )


def turning_error(plan: RenderPlan, camera: str, why: str) -> SpecError:
    return SpecError(
        [
            plan.source.diagnostic(
                ("observation",),
                f"camera '{camera}' cannot be batched ({why}): a batch "
                "renders every env through one custom camera with one lens; it follows a camera that moves (each env's copy "
                "moved) and turns (each env's rays turned), but no move of a copy zooms like a lens (a uniform scale about "
                "the camera changes nothing in the image, a scale across its view distorts the shading), and it follows no "
                f"scale or constraint on the camera or its parents; {ONE_PROCESS_EACH}",
            )
        ]
    )


def turning_limit_error(plan: RenderPlan, camera: str, why: str, cause: str = "turns with the state") -> SpecError:
    return SpecError(
        [
            plan.source.diagnostic(
                ("observation",),
                f"camera '{camera}' {cause}: a batch turns each env's "
                f"rays in its camera's shader, {why}; {ONE_PROCESS_EACH}",
            )
        ]
    )


def world_error(plan: RenderPlan, name: str) -> SpecError:
    return SpecError(
        [
            plan.source.diagnostic(
                ("actors", name),
                "the world (its sky's strength, rotation or tint) is bound to the state: "
                f"a batch's envs share one world; {ONE_PROCESS_EACH}",
                key=True,
            )
        ]
    )


def sun_error(plan: RenderPlan, name: str, num_envs: int) -> SpecError:
    return SpecError(
        [
            plan.source.diagnostic(
                ("actors", name),
                f"sun '{name}' is bound to the state: each env of a batch then has "
                f"its own sun, lighting only its own copy through Cycles' light linking, which tells at most {MAX_LINKED_ENVS} "
                f"such sets apart, not {num_envs}; use batches of at most {MAX_LINKED_ENVS} envs (make_vec(..., workers=K) "
                f"runs several), or {ONE_PROCESS_EACH}",
                key=True,
            )
        ]
    )


def sun_world_error(plan: RenderPlan, name: str) -> SpecError:
    return SpecError(
        [
            plan.source.diagnostic(
                ("actors", name),
                f"sun '{name}' is bound to the state while the world is not one "
                "colour (an image sky, or a .blend file's world with textures): each env of a batch then has its own sun "
                "(Cycles' light linking), and with such a world Cycles' light sampling lit all but one env's copy otherwise "
                "than one env alone (most of a tile's pixels off); use a world colour, or "
                f"{ONE_PROCESS_EACH}",
                key=True,
            )
        ]
    )


def check_batchable(plan: RenderPlan, num_envs: int = 1) -> None:
    """Raise what a batch of this plan cannot render, as far as the spec's own objects tell (ValueError for the engine)."""
    engine = plan.settings.engine
    if engine != "cycles":
        raise ValueError(engine_message(engine))
    objects = plan.scene.objects
    bound: dict[str, set[str]] = {}
    for target in plan.bindings:
        bound.setdefault(target.object, set()).add(target.property)
    distractions = plan.distractions
    orbiting = distractions is not None and distractions.camera and distractions.largest > 0
    for view in plan.views.values():
        why = spec_turning(plan, view.camera, bound)
        if why:
            raise turning_error(plan, view.camera, why)
        if spec_turns(plan, view.camera, bound) or model_turns(plan, view.camera):
            check_turning(plan, view.camera, view.color, num_envs)
        elif orbiting:
            check_turning(plan, view.camera, view.color, num_envs, "turns with its distraction (the camera's orbit)")
    for name in bound:
        if name == WORLD_ACTOR and name not in objects and not plan.scene.file:
            raise world_error(plan, name)
        spec = objects.get(name)
        if isinstance(spec, LightObject) and spec.light == "sun" and num_envs > MAX_LINKED_ENVS:
            raise sun_error(plan, name, num_envs)
        if (
            isinstance(spec, LightObject)
            and spec.light == "sun"
            and num_envs > 1
            and plan.scene.world is not None
            and plan.scene.world.image is not None
        ):
            raise sun_world_error(plan, name)


def check_turning(
    plan: RenderPlan, camera: str, color: str, num_envs: int, cause: str = "turns with the state"
) -> None:
    """Refuse what a batch of a turning camera cannot render: more envs than its shader holds, depth along turned rays."""
    if num_envs > MAX_TURNING_ENVS:
        raise turning_limit_error(
            plan,
            camera,
            f"which holds at most {MAX_TURNING_ENVS} envs, not {num_envs}; use batches of "
            f"at most {MAX_TURNING_ENVS} envs (make_vec(..., workers=K) runs several)",
            cause,
        )
    if color == "depth":
        raise turning_limit_error(
            plan, camera, "while a depth observation is measured along one camera's forward axis for every env", cause
        )


def model_turns(plan: RenderPlan, camera: str) -> bool:
    """Whether `camera` is a camera of the MuJoCo model (not the spec's own) that turns: on a moving body, or aimed at one."""
    if plan.physics is None or camera in plan.scene.objects:
        return False
    return any(info.name == camera and info.turns for info in plan.physics.cameras)


def spec_turns(plan: RenderPlan, camera: str, bound: dict[str, set[str]]) -> bool:
    """Whether the state turns a spec-declared camera: a rotation or look_at bound on it or an ancestor, or it is aimed and moves."""
    objects = plan.scene.objects
    spec = objects.get(camera)
    aimed = isinstance(spec, CameraObject) and spec.look_at is not None
    name: str | None = camera
    seen: set[str] = set()
    while name is not None and name in objects and name not in seen:
        seen.add(name)
        props = bound.get(name, set())
        if props & set(TURNS) or (aimed and props & {"location"}):
            return True
        name = objects[name].parent
    return False


def spec_turning(plan: RenderPlan, camera: str, bound: dict[str, set[str]]) -> str | None:
    """What zooms or scales a spec-declared camera (a binding on it or on a spec-declared ancestor), or None."""
    objects = plan.scene.objects
    name: str | None = camera
    seen: set[str] = set()
    while name is not None and name in objects and name not in seen:
        seen.add(name)
        props = bound.get(name, set())
        turning = (props & set(UNFOLLOWED)) | (props & {"lens"} if name == camera else set())
        if turning:
            return f"its {', '.join(sorted(turning))} binding on '{name}'"
        name = objects[name].parent
    return None
