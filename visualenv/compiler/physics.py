"""The compiler's part for a spec's ``physics:`` section: the model's names in scope, and the calls into the simulation.

The generated step of a physics spec reads, in order: the action's inputs; the
model's values before the step (for ``dynamics.let`` and ``update``, which read
the old state); the simulation's ``frame_skip`` steps with the inputs named
``ctrl_<actuator>`` as controls; the model's values after the step (for the
reward, the outcomes and the observation, which read the new state). Each read
is one call that gathers only the names the expressions use
(:meth:`~visualenv.physics.simulation.Simulation.reader`), made once per env.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass, field
from typing import Any

from visualenv.errors import did_you_mean
from visualenv.expr import BOOL, NUM, Type
from visualenv.expr.codegen import local, name, tuple_of
from visualenv.physics.model import SETTABLE, PhysicsError, PhysicsModel, load_model, resolve_model_path
from visualenv.physics.scene import PhysicsScene, physics_scene
from visualenv.bindables import BINDABLES
from visualenv.spec.models import Physics

#: the generated functions' globals that call into one env's simulation (bound by Program.functions)
READ_PREFIX = "_phys_read_"
ADVANCE = "_phys_advance"
WRITE_RESET = "_phys_write_reset"
#: a reset's redraw loop (visualenv.compiler.physics_reset): its writer, its range of tries, its fault when none met `until`
WRITE_REDRAW = "_phys_write_redraw"
REDRAW_TRIES = "_phys_redraw_tries"
REDRAW_FAILED = "_phys_redraw_failed"
#: a reset's search loop (physics.reset.search): its writer, its range of tries, its fault when none met `until`
WRITE_SEARCH = "_phys_write_search"
SEARCH_TRIES = "_phys_search_tries"
SEARCH_FAILED = "_phys_search_failed"
#: the reset's settling steps and last forward, after a redraw or a settle
FINISH_RESET = "_phys_finish_reset"


@dataclass
class PhysicsPlan:
    """What an env needs to run a physics spec: the model, and which names each generated read gathers."""

    model: PhysicsModel
    frame_skip: int
    keyframe: int | None
    contacts: dict[str, tuple[int, int]]
    controls: list[str] = field(default_factory=list)  # inputs that drive actuators (ctrl_<actuator>), in input order
    moved: list[str] = field(default_factory=list)  # mocap names dynamics.update sets, written before each MuJoCo step
    reset_targets: list[str] = field(default_factory=list)  # qpos/qvel names the reset writes, in order
    reads: dict[str, list[str]] = field(default_factory=dict)  # read name -> physics names it gathers
    observe_size: int = 0  # values in the state-only observation
    scene: PhysicsScene | None = None  # what a renderer draws (made when the spec renders)
    convention: str = "gymnasium"  # whose MuJoCo calls step and reset it (visualenv.physics.conventions)
    finishes: bool = (
        False  # the reset goes on after its values (a redraw, search or settle), and ends with its own forward
    )
    redraw_targets: list[str] = field(default_factory=list)  # what each try of the redraw writes, in order
    redraw_attempts: int = 0
    search_targets: list[str] = field(default_factory=list)  # what each try of the search writes, in order
    search_attempts: int = 0
    settle: tuple[int, float | None] | None = None  # the reset's settling steps and the time set after them
    # geoms whose model position the reset writes: drawn posed from geom_xpos/geom_xmat
    posed_geoms: tuple[int, ...] = ()

    @property
    def dt(self) -> float:
        return self.model.timestep * self.frame_skip

    def simulation(self) -> Any:
        """A fresh Simulation (its own MjModel copy and MjData) for one env."""
        from visualenv.physics.simulation import Simulation

        return Simulation(self.model, self.frame_skip, self.contacts, self.convention)

    def bind(self, env: dict[str, Any], sim: Any) -> None:
        """Put one env's reads, stepper and reset writer into a generated function's globals."""
        for key, names in self.reads.items():
            env[READ_PREFIX + key] = sim.reader(names, key)
        env[ADVANCE] = sim.stepper(self.controls, self.moved)
        env[WRITE_RESET] = sim.writer(self.reset_targets, forward=not self.finishes)
        if self.redraw_attempts:
            env[WRITE_REDRAW] = sim.writer(self.redraw_targets)
            env[REDRAW_TRIES] = range(self.redraw_attempts)
            env[REDRAW_FAILED] = redraw_failure(self.redraw_attempts)
        if self.search_attempts:
            env[WRITE_SEARCH] = sim.writer(self.search_targets)
            env[SEARCH_TRIES] = range(self.search_attempts)
            env[SEARCH_FAILED] = redraw_failure(self.search_attempts, "search")
        if self.finishes:
            env[FINISH_RESET] = reset_finisher(sim, self.settle)

    def written(self) -> list[str]:
        """Every name the reset writes: its values', its redraw's and its search's."""
        return [*self.reset_targets, *self.redraw_targets, *self.search_targets]

    def poses(self, data: Any) -> tuple:
        """What a renderer poses the drawn model from (xpos, xquat, cam_xpos, cam_xmat, light_xpos, light_xdir), geoms a
        reset moves included as bodies of their own (:mod:`visualenv.physics.geom_poses`); live views of `data` without them."""
        from visualenv.physics.geom_poses import render_poses

        return render_poses(data, self.posed_geoms)

    def batch(self, sims: list[Any], workers: int | None = None) -> Any:
        """The envs' simulations stepped and read together (:class:`~visualenv.physics.batch.BatchSimulation`)."""
        from visualenv.physics.batch import BatchSimulation
        from visualenv.physics.model_fields import is_writable

        table = self.model.names.values
        written = any(is_writable(table[n][0]) for n in self.written())
        return BatchSimulation(sims, self.reads, self.controls, workers, self.moved, models_written=written)

    def bind_batch(self, env: dict[str, Any], batch: Any) -> None:
        """Put a batch's column reads and its MuJoCo step into a vectorised function's globals."""
        for key, names in self.reads.items():
            env[READ_PREFIX + key] = batch.reader(names, key)
        env[ADVANCE] = batch.advance


def redraw_failure(attempts: int, loop: str = "redraw") -> Any:
    """The call a redraw (or search) loop makes when no try met its condition: a fault the env locates at
    ``physics.reset.<loop>.until``."""

    def fail() -> None:
        from visualenv.physics.simulation import PhysicsFault

        raise PhysicsFault(
            f"none of {attempts} tries met the condition (physics.reset.{loop}.attempts): "
            f"{'draw' if loop == 'redraw' else 'step'} the values differently, or allow more attempts"
        )

    return fail


def reset_finisher(sim: Any, settle: tuple[int, float | None] | None) -> Any:
    """finish(): the reset's settling steps and the time set (:meth:`~visualenv.physics.simulation.Simulation.settle`),
    then the convention's forward, as dm_control's ``after_reset`` ends a task's ``initialize_episode``."""
    from visualenv.physics.conventions import forward_function

    forward, model, data = forward_function(sim.convention, sim.mujoco), sim.model, sim.data

    def finish() -> None:
        if settle is not None:
            sim.settle(*settle)
        forward(model, data)

    return finish


def load(section: Physics, base_dir: Any, max_image_pixels: int) -> PhysicsModel:
    """The section's MJCF, compiled; PhysicsError says why not (missing mujoco, file, include, bad XML, too large)."""
    return load_model(resolve_model_path(section.model, base_dir), section.max_memory_mib, max_image_pixels)


def scope(model: PhysicsModel, contacts: dict[str, Any]) -> dict[str, Type]:
    """Every name the model adds to expressions: numbers, and the declared contacts (conditions)."""
    names: dict[str, Type] = {n: NUM for n in model.names.values}
    names.update({n: BOOL for n in contacts})
    return names


def read_statement(key: str, names: list[str]) -> ast.stmt:
    """``(_v_a, _v_b, ...) = _phys_read_<key>()``: the named values as the generated code's locals."""
    call = ast.Call(name(READ_PREFIX + key), [], [])
    if len(names) == 1:
        return ast.Assign([ast.Name(local(names[0]), ast.Store())], ast.Subscript(call, ast.Constant(0), ast.Load()))
    target = ast.Tuple([ast.Name(local(n), ast.Store()) for n in names], ast.Store())
    return ast.Assign([target], call)


def call_statement(function: str, values: list[str]) -> ast.stmt:
    """``_phys_<function>((_v_a, _v_b, ...))``."""
    return ast.Expr(ast.Call(name(function), [tuple_of([name(local(v)) for v in values])], []))


def advance_statement(plan: PhysicsPlan) -> ast.stmt:
    """``_phys_advance((_v_ctrl_a, ..., _new_mocap_b_x, ...))``: the controls, then the mocap poses dynamics.update set."""
    values: list[ast.expr] = [name(local(c)) for c in plan.controls]
    values += [name("_new_" + m) for m in plan.moved]
    return ast.Expr(ast.Call(name(ADVANCE), [tuple_of(values)], []))


def settable(model: PhysicsModel) -> set[str]:
    """The names a spec writes to the model: joint values (qpos_/qvel_, in physics.reset.values) and mocap poses (there and
    in dynamics.update)."""
    return {n for n, (array, _) in model.names.values.items() if array in SETTABLE}


def model_object_problem(plan: PhysicsPlan, obj_name: str, prop: str, declared: set[str]) -> str | None:
    """Why an actor cannot bind `prop` on `obj_name`, an object of the model; None if it can (or it is no model object).

    A pose (location, rotation, scale, look_at) cannot be bound on an object that stands for a body of the model (its geom,
    an object named as the body, the body's ``body:<name>`` frame) nor on the model's cameras and lights: MuJoCo poses
    them, so a binding would move the picture and not the physics. A ``body:`` frame takes no binding at all (its geoms do).
    """
    idents = plan.model.names.ident
    bodies = {b: i for i, b in enumerate(idents["body"]) if i}  # the world body never moves: no object stands for it
    frame = obj_name.startswith("body:") and obj_name not in declared
    if frame and obj_name[5:] not in bodies:
        return f"no body '{obj_name[5:]}' in the MuJoCo model for '{obj_name}'" + did_you_mean(
            obj_name[5:], bodies
        ).replace("names:", "bodies:")
    if not BINDABLES[prop].moves:
        if not frame:
            return None
        drawn = [g.name for g in plan.scene.geoms if g.body == bodies[obj_name[5:]]] if plan.scene is not None else []
        return (
            f"'{obj_name}' is the frame of the MuJoCo body '{obj_name[5:]}': bind its geoms by their names instead"
            + (f" ({', '.join(drawn)})" if drawn else "")
        )
    geoms = [g.name for g in plan.scene.geoms] if plan.scene is not None else idents["geom"]
    body = bodies.get(obj_name[5:] if frame else obj_name) if frame or obj_name in bodies else None
    if body is None and obj_name in geoms and obj_name not in declared:
        body = int(plan.model.model.geom_bodyid[idents["geom"].index(obj_name)])
    if body is None:
        if obj_name in declared or obj_name not in [*idents["camera"], *idents["light"]]:
            return None
        return (
            f"'{obj_name}' is a {'camera' if obj_name in idents['camera'] else 'light'} of the MuJoCo model, which MuJoCo poses "
            f"every step: binding its {prop} would fight MuJoCo's pose. Move the body it hangs on, or use an object of the spec's own"
        )
    what = f"the MuJoCo body '{idents['body'][body]}'" if body else "the MuJoCo model's world body (static geoms)"
    return (
        f"'{obj_name}' stands for {what}: binding its {prop} would move the picture and not the physics. "
        f"{how_to_move(plan.model, body)}"
    )


def how_to_move(physics: PhysicsModel, body: int) -> str:
    """How a spec moves `body`: its mocap pose, its joints' values, or what to change in the MJCF."""
    model, ident = physics.model, physics.names.ident["body"][body]
    if body and int(model.body_mocapid[body]) >= 0:
        return (
            f"It is a mocap body: set mocap_{ident}_x, _y, _z (and _qw, _qx, _qy, _qz) in physics.reset.values or "
            "dynamics.update"
        )
    joints = [physics.names.ident["joint"][j] for j in range(model.njnt) if int(model.jnt_bodyid[j]) == body]
    if joints:
        names = [n for n in physics.qpos_names() if any(n == f"qpos_{j}" or n.startswith(f"qpos_{j}_") for j in joints)]
        return f"Its joints move it: set {', '.join(names)} in physics.reset.values, or drive them through actuators"
    where = f"make '{ident}' a mocap body" if body else "put the geoms in a body of their own that is a mocap body"
    return (
        f'To move a body that has no joint, {where} (<body name="{ident if body else "target"}" mocap="true">, a child of '
        "worldbody) and set its mocap_<body>_x, _y, _z in physics.reset.values or dynamics.update; or give it a joint"
    )


#: the read of the model before its step: the only one a batch's replay of one env's step takes from the batch
BEFORE = "before"

__all__ = [
    "ADVANCE",
    "BEFORE",
    "FINISH_RESET",
    "REDRAW_FAILED",
    "REDRAW_TRIES",
    "SEARCH_FAILED",
    "SEARCH_TRIES",
    "WRITE_REDRAW",
    "WRITE_SEARCH",
    "WRITE_RESET",
    "PhysicsError",
    "PhysicsPlan",
    "advance_statement",
    "call_statement",
    "how_to_move",
    "load",
    "model_object_problem",
    "physics_scene",
    "read_statement",
    "scope",
    "settable",
]
