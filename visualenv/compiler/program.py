"""Compile a validated spec into a :class:`Program`: resolved names, generated functions.

Everything a running env needs is decided here, once: parameter values, the
order of state variables, the action space, and three generated functions:

* ``init(params...)  -> state``                      (draws at reset)
* ``step(state, action, steps, fired) -> (state, reward, outcome, fired)``
* ``bind(state, steps) -> values``                 (actor bindings, before a render)

Every expression is checked against the names in scope where it is used, and
all problems are reported together with their spec positions. The program
knows nothing of pixels: it lists binding targets for whatever renderer plugs in.
"""

from __future__ import annotations

import ast
import importlib
import re
import keyword
from dataclasses import dataclass, field
from typing import Any, Callable, Collection, Mapping

from visualenv.errors import Diagnostic, ExpressionError, SpecError, did_you_mean, in_file_order
from visualenv.expr import BOOL, NUM, Checked, RandomSource, Type, check, vec
from visualenv.expr.codegen import FunctionBuilder, LineMap, Site, const, function_globals, local, lower, name, tuple_of
from visualenv.expr.functions import CONSTANTS, FUNCTIONS, bind_random
from visualenv.compiler.vectorized import vectorizable, vectorize
from visualenv.compiler import physics as phys
from visualenv.compiler.physics_reset import build_reset
from visualenv.spec.options import WHERE as OPTIONS_WHERE
from visualenv.render.base import BindingTarget, RenderPlan
from visualenv.spec.loader import LoadedSpec
from visualenv.spec.bindables import BINDABLES, WORLD_ACTOR, WORLD_PROPERTIES, camera_problem, type_problem
from visualenv.spec.models import CameraObject, EmptyObject, LightObject, MeshObject, PrimitiveObject, Spec

#: names every expression may read besides the spec's own (not all in every context)
BUILTIN_NAMES = ("steps", "max_steps", "dt", "action")
_RESERVED = set(FUNCTIONS) | set(CONSTANTS) | set(BUILTIN_NAMES) | set(keyword.kwlist) | {"True", "False", "None"}

def checked_dynamics(func: Callable[..., Any], state_names: list[str]) -> Callable[..., Mapping[str, float]]:
    """The Python hook, its answer checked: a dict of numbers for state variables (missing ones keep their value).

    Anything else, or an exception in the hook, is a ValueError, which the env
    reports as a fault located at ``dynamics.python`` with the step's values.
    """
    known = set(state_names)

    def call(state: dict, inputs: dict, params: dict, rng: Any) -> dict[str, float]:
        try:
            out = func(state, inputs, params, rng)
        except Exception as exc:  # noqa: BLE001 - the user's code: any failure becomes a located fault
            raise ValueError(f"the function raised {type(exc).__name__}: {exc}") from exc
        if not isinstance(out, Mapping):
            raise ValueError(f"the function returned {type(out).__name__}, expected a dict of new state values (state: {', '.join(state_names)})")
        unknown = [str(k) for k in out if k not in known]
        if unknown:
            raise ValueError(f"the function returned {', '.join(map(repr, unknown))}, which is not state" + did_you_mean(unknown[0], state_names).replace("names:", "state:"))
        new = {}
        for key, value in out.items():
            try:
                new[key] = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"the function returned {key}={value!r}, expected a number") from None
        return new

    return call


#: the expression type of each kind of binding value (BINDABLES' ``value``); a colour's size (3 or 4) is checked apart
VALUE_TYPES: dict[str, Type] = {"vector": vec(3), "scale": vec(3), "color": vec(0), "number": NUM, "condition": BOOL}
#: the Blender object type each kind of declared object becomes
OBJECT_TYPES = ((PrimitiveObject, "MESH"), (MeshObject, "MESH"), (LightObject, "LIGHT"), (CameraObject, "CAMERA"), (EmptyObject, "EMPTY"))


def object_type(obj: Any) -> str:
    """The Blender object type (MESH, LIGHT, CAMERA, EMPTY) a declared scene object becomes."""
    return next(t for cls, t in OBJECT_TYPES if isinstance(obj, cls))


@dataclass(frozen=True)
class OutcomeRule:
    name: str
    end: str  # terminate | truncate | none
    success: bool


@dataclass
class Program:
    """A compiled spec: what an env needs at run time."""

    loaded: LoadedSpec
    params: dict[str, float | bool]
    state_names: list[str]
    observed: list[int]
    input_names: list[str]
    discrete: int | None  # number of discrete actions, or None for continuous
    continuous: list[tuple[float, float]]
    outcomes: list[OutcomeRule]
    bindings: list[BindingTarget]
    line_maps: dict[str, LineMap] = field(default_factory=dict)  # per generated function: its lines' spec sites
    physics: "phys.PhysicsPlan | None" = None  # the MuJoCo model and what the generated code reads from it (docs/physics.md)
    _builders: dict[str, FunctionBuilder] = field(default_factory=dict, repr=False)
    _python_dynamics: Callable[..., Any] | None = field(default=None, repr=False)

    @property
    def spec(self) -> Spec:
        return self.loaded.spec

    def functions(self, random: RandomSource, simulation: Any = None) -> "CompiledFunctions":
        """Fresh callables bound to `random` (one set per env), and to the env's `simulation` for a physics spec."""
        env = function_globals(bind_random(random))
        env["_python_dynamics"] = self._python_dynamics
        env["_random"] = random
        if self.physics is not None:
            if simulation is None:
                raise ValueError("a physics spec's functions need the env's simulation (Program.physics.simulation())")
            self.physics.bind(env, simulation)
        built = {key: b.build(env) for key, b in self._builders.items()}
        return CompiledFunctions(built["init"], built["step"], built["bind"], built.get("observe"))

    def batch_functions(self, physics: Any = None) -> "BatchFunctions":
        """The step and bind functions of many envs at once, on numpy columns (None where one must stay per env).

        A physics spec's functions read and step its batch's simulations (`physics`, a
        :class:`~visualenv.physics.batch.BatchSimulation`), its state-only observation too;
        without one, or when its step draws random numbers, each env steps its own.
        """
        if self.physics is not None:
            if physics is None or not vectorizable(self._builders["step"]):
                return BatchFunctions(None, None)
            env: dict[str, Any] = {}
            self.physics.bind_batch(env, physics)
            builders = self._builders
            return BatchFunctions(vectorize(builders["step"], env), vectorize(builders["bind"], env), vectorize(builders["observe"], env))
        return BatchFunctions(vectorize(self._builders["step"]), vectorize(self._builders["bind"]))

    def render_plan(self) -> RenderPlan:
        """What a renderer needs: the scene, the observation cameras, the settings and the binding targets."""
        spec = self.spec
        views = spec.observation.views() if spec.observation is not None else {}
        return RenderPlan(
            scene=spec.scene,
            views=views,
            single=spec.observation is None or spec.observation.cameras is None,
            settings=spec.render,
            bindings=tuple(self.bindings),
            base_dir=self.loaded.base_dir,
            source=self.loaded.source,
            cameras=tuple(spec.camera_uses()),
            physics=self.physics.scene if self.physics is not None else None,
        )


@dataclass(frozen=True)
class CompiledFunctions:
    init: Callable[[], tuple]
    step: Callable[[tuple, Any, int, int], tuple]
    bind: Callable[[tuple, int], tuple]
    observe: Callable[[tuple, int], tuple] | None = None  # a physics spec's state-only observation


@dataclass(frozen=True)
class BatchFunctions:
    step: Callable[[tuple, Any, Any, Any], tuple] | None
    bind: Callable[[tuple, Any], tuple] | None
    observe: Callable[[tuple, Any], tuple] | None = None  # a physics spec's state-only observation


def compile_spec(loaded: LoadedSpec, params: Mapping[str, Any] | None = None) -> Program:
    """Resolve and check every expression in `loaded`; raise SpecError listing all problems."""
    return _Compiler(loaded, dict(params or {})).run()


class _Compiler:
    def __init__(self, loaded: LoadedSpec, overrides: dict[str, Any]):
        self.loaded = loaded
        self.spec = loaded.spec
        self.smap = loaded.source
        self.overrides = overrides
        self.problems: list[Diagnostic] = []
        self.used: set[str] = set()  # every name a checked expression read, so far
        self.plan: phys.PhysicsPlan | None = None
        self.pnames: dict[str, Type] = {}  # the physics model's names (empty without physics)

    # -- reporting ------------------------------------------------------------------------------

    def error(self, path: tuple, message: str, *, key: bool = False, column: int | None = None) -> None:
        self.problems.append(self.smap.diagnostic(path, message, key=key, column_offset=column))

    def expr(self, path: tuple, text: Any, names: Mapping[str, Type], *, expect: Type | None = None, random: bool = True) -> Checked | None:
        try:
            checked = check(text, names, constants=self.params, allow_random=random, expect=expect)
            self.used |= checked.names
            return checked
        except ExpressionError as exc:
            self.error(path, self.explain_order(path, exc.message), column=exc.offset)
            return None

    def explain_order(self, path: tuple, message: str) -> str:
        """An unknown name defined further down the same section is an ordering problem."""
        match = re.match(r"unknown name '(\w+)'", message)
        if not match or len(path) < 2:
            return message
        wanted = match.group(1)
        sections = {("params",): list(self.spec.params), ("dynamics", "let"): list(self.spec.dynamics.let), ("state",): list(self.spec.state)}
        for prefix, names in sections.items():
            if tuple(path[: len(prefix)]) == prefix and wanted in names:
                where = ".".join(prefix)
                if len(path) > len(prefix) and path[len(prefix)] == wanted:
                    return f"unknown name '{wanted}': '{wanted}' cannot be used in its own definition in {where} (cyclic definitions are not allowed)"
                return (f"unknown name '{wanted}': '{wanted}' is defined later in {where}: an entry can only use the ones above it "
                        "(reorder them; cyclic definitions are not allowed)")
        return message

    # -- the passes -----------------------------------------------------------------------------

    def run(self) -> Program:
        spec = self.spec
        self.load_physics()
        self.check_names()
        self.params = self.resolve_params()
        state_names = list(spec.state)
        input_names, discrete, continuous = self.resolve_actions()
        builders = {"init": self.build_init(state_names), "step": self.build_step(state_names, input_names, discrete)}
        builders["bind"], bindings = self.build_bindings(state_names)
        if self.plan is not None:
            builders["observe"] = self.build_observe(state_names)
        outcomes = [OutcomeRule(n, o.end, o.success) for n, o in spec.outcomes.items()]
        python_dynamics = self.resolve_python_dynamics()
        if self.problems:
            raise SpecError(in_file_order(self.problems))
        observed = [i for i, n in enumerate(state_names) if spec.state[n].observe]
        return Program(
            self.loaded, self.params, state_names, observed, input_names, discrete, continuous, outcomes, bindings,
            line_maps={k: b.line_map() for k, b in builders.items()}, physics=self.plan, _builders=builders, _python_dynamics=python_dynamics,
        )

    # -- physics ---------------------------------------------------------------------------------

    def load_physics(self) -> None:
        """The MJCF model, its names in scope, its contacts and keyframe resolved; a problem is located at its field."""
        section = self.spec.physics
        if section is None:
            return
        try:
            model = phys.load(section, self.loaded.base_dir)
        except phys.PhysicsError as exc:
            self.error(("physics", "model"), str(exc))
            raise SpecError(in_file_order(self.problems)) from None
        geoms = {n: i for i, n in enumerate(model.names.ident["geom"])}
        contacts: dict[str, tuple[int, int]] = {}
        for key, pair in section.contacts.items():
            if key in model.names.values:
                self.error(("physics", "contacts", key), f"'{key}' is a name of the physics model: choose another", key=True)
            unknown = [(i, g) for i, g in enumerate(pair) if g not in geoms]
            for i, g in unknown:
                self.error(("physics", "contacts", key, i), f"no geom '{g}' in the model" + did_you_mean(g, geoms).replace("names:", "geoms:"))
            if not unknown:
                contacts[key] = (geoms[pair[0]], geoms[pair[1]])
        keyframe = None
        if section.reset.keyframe is not None:
            keys = {n: i for i, n in enumerate(model.names.ident["key"])}
            keyframe = keys.get(section.reset.keyframe)
            if keyframe is None:
                self.error(("physics", "reset", "keyframe"), f"no keyframe '{section.reset.keyframe}' in the model"
                           + did_you_mean(section.reset.keyframe, keys).replace("names:", "keyframes:"))
        if "dt" in self.spec.model_fields_set:
            self.error(("dt",), "with physics, dt is the model's timestep times physics.frame_skip: leave 'dt' out", key=True)
        self.plan = phys.PhysicsPlan(model, section.frame_skip, keyframe, contacts, convention=section.convention)
        if self.spec.observation is not None or self.spec.render.view.camera:  # drawn: every geom must be drawable
            try:
                self.plan.scene = phys.physics_scene(model)
            except phys.PhysicsError as exc:
                self.error(("physics", "model"), str(exc))
        self.pnames = phys.scope(model, section.contacts)

    def physics_objects(self) -> dict[str, str]:
        """The objects the renderer makes of the model (drawn geoms, lights, cameras) by name, with their Blender types."""
        if self.plan is None or self.plan.scene is None:
            return {}
        scene = self.plan.scene
        return {**{g.name: "MESH" for g in scene.geoms}, **{light.name: "LIGHT" for light in scene.lights}, **{c.name: "CAMERA" for c in scene.cameras}}

    def physics_reads(self, fb: FunctionBuilder, key: str, at: int, used: set[str], exclude: Collection[str] = ()) -> None:
        """Insert, at statement `at` of `fb`, the read of the physics names in `used` (a statement without a site of its own)."""
        if self.plan is None:
            return
        names = sorted(n for n in used if n in self.pnames and n not in exclude)
        self.plan.reads[key] = names
        if names:
            stmt = phys.read_statement(key, names)
            fb.add(stmt)
            fb.body.insert(at, fb.body.pop())

    def build_reset(self, fb: FunctionBuilder) -> None:
        """The physics reset: its values, redraw and settling steps (:mod:`visualenv.compiler.physics_reset`), before the state's init."""
        build_reset(self, fb)

    def build_observe(self, state_names: list[str]) -> FunctionBuilder:
        """observe(state, steps): the state-only observation of a physics spec (physics.observe, or every qpos and qvel, then the observed state)."""
        assert self.plan is not None and self.spec.physics is not None
        fb = FunctionBuilder("observe", ["_state", "_steps"])
        fb.unpack([local(n) for n in state_names], "_state")
        fb.assign(local("steps"), name("_steps"))
        scope: dict[str, Type] = {**self.pnames, **{n: NUM for n in state_names}, "steps": NUM}
        entries = self.spec.physics.observe
        if entries is None:
            model = self.plan.model
            entries = [*model.qpos_names(), *model.qvel_names(), *(n for n in state_names if self.spec.state[n].observe)]
        start, before = len(fb.body), set(self.used)
        self.used = set()
        values: list[ast.expr] = []
        for i, entry in enumerate(entries):
            path = ("physics", "observe", i) if self.spec.physics.observe is not None else ("physics",)
            checked = self.expr(path, entry, scope, expect=NUM)
            if checked:
                fb.assign(f"_o{i}", lower(checked.tree), Site(".".join(map(str, path)), checked.text, tuple(sorted(checked.names))))
                values.append(name(f"_o{i}"))
        self.physics_reads(fb, "observe", start, self.used, set(state_names))
        self.plan.observe_size = len(values)
        self.used |= before
        fb.returns(tuple_of(values))
        return fb

    def check_names(self) -> None:
        """User names must not shadow built-ins or each other."""
        spec = self.spec
        seen: dict[str, str] = {}
        groups: list[tuple[str, list[str]]] = [
            ("params", list(spec.params)), ("state", list(spec.state)),
            ("dynamics.let", list(spec.dynamics.let)),
        ]
        if spec.actions is not None and spec.actions.discrete:
            groups.append(("actions.discrete", list(dict.fromkeys(k for a in spec.actions.discrete for k in a))))
        elif spec.actions is not None and spec.actions.continuous:
            groups.append(("actions.continuous", list(spec.actions.continuous)))
        # a contact is a name too (load_physics checks it against the model's own, which self.pnames holds with it)
        for group, names in [*groups, ("physics.contacts", list(getattr(spec.physics, "contacts", {})))]:
            for n in names:
                path: tuple = tuple(group.split(".")) + (n,)
                if group == "actions.discrete":
                    index = next(i for i, a in enumerate((spec.actions.discrete if spec.actions else None) or []) if n in a)
                    path = ("actions", "discrete", index, n)
                if n in _RESERVED:
                    self.error(path, f"'{n}' is a reserved name (a built-in, function or keyword): choose another", key=True)
                elif n in seen and not (group == "actions.discrete" and seen[n] == group):
                    self.error(path, f"'{n}' is already defined in {seen[n]}", key=True)
                else:
                    seen[n] = group
        for group, names in groups:
            for n in names:
                path = ("actions", "discrete") if group == "actions.discrete" else tuple(group.split(".")) + (n,)
                if n in self.pnames and not (group.startswith("actions") and n.startswith("ctrl_")):
                    self.error(path, f"'{n}' is a name of the physics model: choose another", key=True)
                elif self.plan is not None and group.startswith("actions") and n.startswith("ctrl_") and n not in self.pnames:
                    controls = [f"ctrl_{a}" for a in self.plan.model.actuator_names()]
                    self.error(path, f"no actuator '{n[5:]}' in the model for '{n}'" + did_you_mean(n, controls).replace("names:", "controls:"), key=True)
        if "max_steps" in spec.outcomes:
            self.error(("outcomes", "max_steps"), "'max_steps' is what info['outcome'] says when an episode reaches max_steps: choose another name", key=True)
        for n in spec.dynamics.update:
            if n not in spec.state:
                self.error(("dynamics", "update", n), f"'{n}' is not a state variable" + did_you_mean(n, spec.state).replace("names:", "state:"), key=True)

    def resolve_params(self) -> dict[str, float | bool]:
        params: dict[str, float | bool] = {}
        for key in self.overrides:
            if key not in self.spec.params:
                raise SpecError([Diagnostic(OPTIONS_WHERE, None, None, f"params.{key}", f"unknown parameter override '{key}'" + did_you_mean(key, self.spec.params))])
        raw = {**self.spec.params, **self.overrides}
        builtins = {"max_steps": float(self.spec.max_steps), "dt": float(self.plan.dt if self.plan is not None else self.spec.dt)}
        self.params = {}
        for key, value in raw.items():
            if isinstance(value, bool):
                params[key] = value
            else:
                try:
                    checked = check(value, {}, constants={**builtins, **params}, allow_random=False)
                except ExpressionError as exc:
                    self.param_error(key, self.explain_order(("params", key), exc.message), column=exc.offset)
                    continue
                if checked.constant is None or isinstance(checked.constant, tuple):
                    self.param_error(key, "a parameter must be a number or a condition")
                    continue
                params[key] = checked.constant
        return {**builtins, **params}

    def param_error(self, key: str, message: str, *, column: int | None = None) -> None:
        """A bad param: blamed on the override when the value came from make(params=...), else on the spec's line.

        A bad override stops compiling at once: the params that use it would only repeat the problem.
        """
        if key in self.overrides:
            raise SpecError([Diagnostic(OPTIONS_WHERE, None, None, f"params.{key}", f"{message} (in the override {self.overrides[key]!r})")])
        self.error(("params", key), message, column=column)

    def resolve_actions(self) -> tuple[list[str], int | None, list[tuple[float, float]]]:
        actions = self.spec.actions
        if actions is None:  # a physics spec's default: one Box dimension per actuator, in its ctrlrange (Gymnasium's action space)
            assert self.plan is not None
            model = self.plan.model
            names = [f"ctrl_{a}" for a in model.actuator_names()]
            self.plan.controls = names
            return names, None, [model.ctrl_range(i) for i in range(len(names))]
        if self.plan is not None:
            self.plan.controls = [n for n in self.input_names_of(actions) if n.startswith("ctrl_") and n in self.pnames]
        if actions.discrete is not None:
            names = list(dict.fromkeys(k for a in actions.discrete for k in a))
            return names, len(actions.discrete), []
        assert actions.continuous is not None
        return list(actions.continuous), None, [(c.low, c.high) for c in actions.continuous.values()]

    @staticmethod
    def input_names_of(actions: Any) -> list[str]:
        if actions.discrete is not None:
            return list(dict.fromkeys(k for a in actions.discrete for k in a))
        return list(actions.continuous or {})

    def resolve_python_dynamics(self) -> Callable[..., Any] | None:
        target = self.spec.dynamics.python
        if not target:
            return None
        if self.spec.dynamics.update or self.spec.dynamics.let:
            self.error(("dynamics", "python"), "'python' dynamics replace 'let' and 'update': give one or the other")
        module_name, func_name = target.split(":")
        try:
            module = importlib.import_module(module_name)
            func = getattr(module, func_name)
        except Exception as exc:  # noqa: BLE001 - any import failure is reported, located
            self.error(("dynamics", "python"), f"cannot import '{target}': {type(exc).__name__}: {exc}")
            return None
        if not callable(func):
            self.error(("dynamics", "python"), f"'{target}' is not callable")
            return None
        return checked_dynamics(func, list(self.spec.state))

    # -- generated functions --------------------------------------------------------------------

    def build_init(self, state_names: list[str]) -> FunctionBuilder:
        """init(): each state variable in order; an init may read earlier ones."""
        fb = FunctionBuilder("init", [])
        scope: dict[str, Type] = {}
        if self.plan is not None:  # the model's reset first: the state's init may read the model's values
            self.build_reset(fb)
            scope.update(self.pnames)
        start, before = len(fb.body), set(self.used)
        self.used = set()
        for n in state_names:
            path = ("state", n, "init")
            checked = self.expr(path, self.spec.state[n].init, scope, expect=NUM)
            if checked:
                fb.assign(local(n), lower(checked.tree), Site(".".join(map(str, path)), checked.text, tuple(sorted(checked.names))))
            scope[n] = NUM
        self.physics_reads(fb, "init", start, self.used, set(state_names))
        self.used |= before
        fb.returns(tuple_of([name(local(n)) for n in state_names]))
        return fb

    def build_step(self, state_names: list[str], input_names: list[str], discrete: int | None) -> FunctionBuilder:
        """The step function: inputs from the action, derived values, the simultaneous update, then reward and outcomes."""
        fb = FunctionBuilder("step", ["_state", "_action", "_steps", "_fired"])
        fb.unpack([local(n) for n in state_names], "_state")
        fb.assign(local("steps"), name("_steps"))
        scope: dict[str, Type] = {**self.pnames, **{n: NUM for n in state_names}}
        scope["steps"] = NUM
        if discrete is not None:
            self.step_discrete_inputs(fb, scope, input_names, discrete)
        else:
            self.step_continuous_inputs(fb, input_names)
        for n in input_names:
            scope[n] = NUM
        start, before = len(fb.body), set(self.used)
        self.used = set()
        self.step_let(fb, scope)
        if self.spec.dynamics.python:
            self.python_call(fb, state_names, input_names)
        else:
            self.step_update(fb, scope, commit=self.plan is None)
        if self.plan is not None:  # the model's values before the step, for let and update; then the step; then the values after it
            self.physics_reads(fb, "before", start, self.used, set(state_names) | set(input_names))
            fb.add(phys.call_statement(phys.ADVANCE, self.plan.controls), Site("physics", f"{self.spec.physics.model if self.spec.physics else ''}: the MuJoCo step"))
            self.commit_update(fb)
            after_at = len(fb.body)
        self.used |= before
        fb.assign(local("steps"), ast.BinOp(name("_steps"), ast.Add(), const(1)))
        before_reward = set(self.used)
        self.used = set()
        # reward and outcomes read the new state
        checked = self.expr(("reward",), self.spec.reward, scope, expect=NUM)
        fb.assign("_reward", lower(checked.tree) if checked else const(0.0), Site("reward", checked.text if checked else "", tuple(sorted(checked.names)) if checked else ()))
        self.step_outcomes(fb, scope)
        if self.plan is not None:
            self.physics_reads(fb, "after", after_at, self.used, set(state_names) | set(input_names) | set(self.spec.dynamics.let))
        self.used |= before_reward
        fb.returns(tuple_of([tuple_of([name(local(n)) for n in state_names]), name("_reward"), name("_outcome"), name("_fired")]))
        return fb

    def step_discrete_inputs(self, fb: FunctionBuilder, scope: dict[str, Type], input_names: list[str], discrete: int) -> None:
        """Every input 0, then the chosen action's inputs (an if-chain on the action index)."""
        fb.assign(local("action"), name("_action"))
        for n in input_names:
            fb.assign(local(n), const(0.0))
        chain: ast.stmt | None = None
        for index in reversed(range(discrete)):
            sub = FunctionBuilder("_", [])
            for n, value in ((self.spec.actions.discrete if self.spec.actions else None) or [])[index].items():
                path = ("actions", "discrete", index, n)
                checked = self.expr(path, value, {**scope, "action": NUM}, expect=NUM)
                if checked:
                    sub.assign(local(n), lower(checked.tree))
            body: list[ast.stmt] = sub.body or [ast.Pass()]
            test = ast.Compare(name("_action"), [ast.Eq()], [const(index)])
            chain = ast.If(test, body, [chain] if chain is not None else [])
        if chain is not None:
            fb.add(chain, Site("actions.discrete", "the chosen action's inputs"))
        scope["action"] = NUM

    def step_continuous_inputs(self, fb: FunctionBuilder, input_names: list[str]) -> None:
        """The action's values, clipped to each input's bounds."""
        fb.unpack([local("_in_" + n) for n in input_names], "_action")
        _, _, ranges = self.resolve_actions()
        for n, (lo, hi) in zip(input_names, ranges):
            clipped = ast.Call(name("_f_clip"), [name(local("_in_" + n)), const(float(lo)), const(float(hi))], [])
            fb.assign(local(n), clipped)

    def step_let(self, fb: FunctionBuilder, scope: dict[str, Type]) -> None:
        """Derived quantities, in order: each may use the ones before it."""
        for n, value in self.spec.dynamics.let.items():
            path = ("dynamics", "let", n)
            checked = self.expr(path, value, scope, expect=NUM)
            if checked:
                fb.assign(local(n), lower(checked.tree), Site(".".join(map(str, path)), checked.text, tuple(sorted(checked.names))))
            scope[n] = NUM

    def step_update(self, fb: FunctionBuilder, scope: dict[str, Type], commit: bool = True) -> None:
        """The simultaneous update: every right-hand side reads the old state, then all are assigned (``commit``; else by commit_update)."""
        spec = self.spec
        new_names = []
        for n, value in spec.dynamics.update.items():
            if n not in spec.state:
                continue
            path = ("dynamics", "update", n)
            checked = self.expr(path, value, scope, expect=NUM)
            if checked:
                fb.assign("_new_" + n, lower(checked.tree), Site(".".join(map(str, path)), checked.text, tuple(sorted(checked.names))))
                new_names.append(n)
        self.updated = new_names
        if commit:
            self.commit_update(fb)

    def commit_update(self, fb: FunctionBuilder) -> None:
        """The new state values become the state (after the physics step, in a physics spec)."""
        for n in getattr(self, "updated", []):
            fb.assign(local(n), name("_new_" + n))

    def step_outcomes(self, fb: FunctionBuilder, scope: dict[str, Type]) -> None:
        """Ending outcomes as an if-chain in spec order (the first that holds wins); milestones fire once each (a bit in _fired)."""
        fb.assign("_outcome", const(-1))
        ending: ast.stmt | None = None
        milestones: list[ast.stmt] = []
        rules = list(self.spec.outcomes.items())
        # milestone i (in spec order) owns bit i of _fired: the env names fired milestones by that order
        milestone_bits = {n: 1 << i for i, n in enumerate(n for n, r in rules if r.end == "none")}
        for index in reversed(range(len(rules))):
            rule_name, rule = rules[index]
            when = self.expr(("outcomes", rule_name, "when"), rule.when, scope, expect=BOOL)
            reward = self.expr(("outcomes", rule_name, "reward"), rule.reward, scope, expect=NUM)
            if not (when and reward):
                continue
            if isinstance(when.tree, ast.Constant) and when.tree.value is False:
                self.error(("outcomes", rule_name, "when"), "this condition is always false: the outcome can never happen")
            add_reward = ast.AugAssign(ast.Name("_reward", ast.Store()), ast.Add(), lower(reward.tree))
            set_outcome = ast.Assign([ast.Name("_outcome", ast.Store())], const(index))
            if rule.end == "none":
                bit = milestone_bits[rule_name]
                not_fired = ast.Compare(ast.BinOp(name("_fired"), ast.BitAnd(), const(bit)), [ast.Eq()], [const(0)])
                mark = ast.AugAssign(ast.Name("_fired", ast.Store()), ast.BitOr(), const(bit))
                milestones.insert(0, ast.If(ast.BoolOp(ast.And(), [not_fired, lower(when.tree)]), [add_reward, mark], []))
            else:
                ending = ast.If(lower(when.tree), [add_reward, set_outcome], [ending] if ending is not None else [])
        if ending is not None:
            fb.add(ending, Site("outcomes", "the outcome conditions"))
        for stmt in milestones:
            fb.add(stmt, Site("outcomes", "the milestone conditions"))

    def python_call(self, fb: FunctionBuilder, state_names: list[str], input_names: list[str]) -> None:
        """Call the trusted 'module:function' escape hatch with plain dicts."""
        def as_dict(names: list[str]) -> ast.expr:
            return ast.Dict([const(n) for n in names], [name(local(n)) for n in names])

        params = ast.Dict([const(k) for k in self.params], [const(v) for v in self.params.values()])
        call = ast.Call(name("_python_dynamics"), [as_dict(state_names), as_dict(input_names), params, ast.Attribute(name("_random"), "generator", ast.Load())], [])
        fb.assign("_py", call, Site("dynamics.python", self.spec.dynamics.python or ""))
        for n in state_names:
            get = ast.Call(ast.Attribute(name("_py"), "get", ast.Load()), [const(n), name(local(n))], [])
            fb.assign(local(n), get, Site("dynamics.python", f"the value returned for '{n}'"))

    def build_bindings(self, state_names: list[str]) -> tuple[FunctionBuilder, list[BindingTarget]]:
        """bind(state, steps): the value of every actor property, flattened in order."""
        fb = FunctionBuilder("bind", ["_state", "_steps"])
        fb.unpack([local(n) for n in state_names], "_state")
        fb.assign(local("steps"), name("_steps"))
        scope: dict[str, Type] = {**self.pnames, **{n: NUM for n in state_names}}  # a physics spec's names too: a camera can follow a body
        scope["steps"] = NUM
        targets: list[BindingTarget] = []
        values: list[ast.expr] = []
        start, before = len(fb.body), set(self.used)
        self.used = set()
        for obj_name, actor in self.spec.actors.items():
            if self.bound_object_known(obj_name):
                for prop in type(actor).model_fields:
                    raw = getattr(actor, prop)
                    if raw is not None:
                        self.bind_property(fb, ("actors", obj_name, prop), raw, scope, targets, values)
        self.physics_reads(fb, "bind", start, self.used, set(state_names))
        self.used |= before
        fb.returns(tuple_of(values))
        self.check_cameras()
        return fb, targets

    def bound_object_known(self, obj_name: str) -> bool:
        """A bound object must be declared, unless a .blend may hold it (the renderer checks those)."""
        declared = self.spec.scene.objects
        if obj_name == WORLD_ACTOR and obj_name not in declared:
            return True  # the world: the spec's, the file's, or the default one
        model_objects = self.physics_objects()
        if obj_name in model_objects and obj_name not in declared:
            return True  # a geom, light or camera of the MuJoCo model (e.g. a colour drawn at reset: domain randomisation)
        if self.spec.scene.file is None and obj_name not in declared:
            known = [*declared, *model_objects]
            self.error(("actors", obj_name), f"no object '{obj_name}' in the scene" + did_you_mean(obj_name, known).replace("names:", "objects:"), key=True)
            return False
        return True

    def bind_property(self, fb: FunctionBuilder, path: tuple, raw: Any, scope: dict[str, Type],
                      targets: list[BindingTarget], values: list[ast.expr]) -> None:
        """One binding: its object's type checked, its values assigned one line each (so a fault names it), its target recorded."""
        _, obj_name, prop = path
        obj = self.spec.scene.objects.get(obj_name)
        if obj is None and obj_name in self.physics_objects():
            problem = type_problem(prop, obj_name, self.physics_objects()[obj_name])
            if problem:
                self.error(path, problem, key=True)
                return
        problem = type_problem(prop, obj_name, object_type(obj)) if obj is not None else None
        world = obj is None and obj_name == WORLD_ACTOR
        if world and prop not in WORLD_PROPERTIES:
            problem = f"the World actor binds the world's {', '.join(map(repr, WORLD_PROPERTIES))}, not '{prop}'"
        if problem:
            self.error(path, problem, key=True)
            return
        checked_values: list[ast.expr] | tuple[ast.expr, int] | None
        if world and prop == "rotation" and not isinstance(raw, list) and not str(raw).strip().startswith("["):
            checked = self.expr(path, raw, scope, expect=NUM)  # one angle: about the vertical axis
            checked_values = [const(0.0), const(0.0), lower(checked.tree)] if checked else None
        else:
            checked_values = self.binding_values(path, prop, raw, scope)
        if checked_values is None:
            return
        text = "[" + ", ".join(map(str, raw)) + "]" if isinstance(raw, list) else str(raw)
        site = Site(".".join(map(str, path)), text, tuple(sorted(scope)))
        if isinstance(checked_values, tuple):  # a vector computed as a whole: evaluate it once
            whole, size = checked_values
            var = f"_b{len(values)}v"
            fb.assign(var, whole, site)
            checked_values = [ast.Subscript(name(var), const(i), ast.Load()) for i in range(size)]
        for item in checked_values:
            var = f"_b{len(values)}"
            fb.assign(var, item, site)
            values.append(name(var))
        targets.append(BindingTarget(obj_name, prop, len(checked_values)))

    def check_cameras(self) -> None:
        """The observation and view cameras of a scene declared in full (a .blend's are checked when it is loaded)."""
        spec = self.spec
        if spec.observation is None or spec.scene.file is not None:
            return
        types = {n: object_type(o) for n, o in spec.scene.objects.items()}
        types.update({n: t for n, t in self.physics_objects().items() if n not in types})  # the model's cameras, by their MuJoCo names
        for path, camera in spec.camera_uses():
            problem = camera_problem(camera, types)
            if problem:
                self.error(path, problem)

    def binding_values(self, path: tuple, prop: str, raw: Any, scope: dict[str, Type]) -> list[ast.expr] | tuple[ast.expr, int] | None:
        """A binding's value as a list of scalar trees, or (vector tree, size) when it is not a literal."""
        kind = BINDABLES[prop].value
        wanted = VALUE_TYPES[kind]
        if wanted.kind == "vec":
            if isinstance(raw, list):
                if kind == "color" and len(raw) not in (3, 4):
                    self.error(path, "a colour needs 3 (RGB) or 4 (RGBA) values")
                    return None
                out = []
                for i, item in enumerate(raw):
                    checked = self.expr(path + (i,), item, scope, expect=NUM)
                    if checked is None:
                        return None
                    out.append(lower(checked.tree))
                return out
            if kind == "scale" and not (isinstance(raw, str) and raw.strip().startswith("[")):
                checked = self.expr(path, raw, scope, expect=NUM)
                return [lower(checked.tree)] * 3 if checked else None
            checked = self.expr(path, raw, scope)
            if checked is None:
                return None
            size = checked.type.size if checked.type.kind == "vec" else 0
            if checked.type.kind != "vec" or (wanted.size and size != wanted.size) or (kind == "color" and size not in (3, 4)):
                need = "3 or 4 values" if kind == "color" else f"a vector of {wanted.size}"
                self.error(path, f"'{prop}' needs {need}, got {checked.type}")
                return None
            tree = lower(checked.tree)
            if isinstance(tree, ast.Tuple):
                return list(tree.elts)
            return tree, size  # e.g. a conditional between vectors: the caller evaluates it once
        checked = self.expr(path, raw, scope, expect=wanted)
        if checked is None:
            return None
        return [lower(checked.tree)]
