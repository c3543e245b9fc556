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
from visualenv.expr import NUM, Checked, RandomSource, Type, check
from visualenv.expr.codegen import FunctionBuilder, LineMap, function_globals, local, name, tuple_of
from visualenv.expr.functions import CONSTANTS, FUNCTIONS, bind_random
from visualenv.compiler.actions import ActionsCompiler
from visualenv.compiler.bindings import BindingsCompiler
from visualenv.compiler.batch_step import vectorizable, vectorize
from visualenv.compiler import physics as phys
from visualenv.compiler.physics_reset import build_reset
from visualenv.compiler.python_hook import checked_dynamics, reference_problem, refuse_untrusted_code
from visualenv.compiler.step_functions import StepCompiler
from visualenv.spec.options import WHERE as OPTIONS_WHERE
from visualenv.compiler.render_plan import scene_plan, to_plan, views_plan
from visualenv.render.plan import BindingTarget, RenderPlan
from visualenv.spec.loader import LoadedSpec
from visualenv.spec.models import Spec

#: names every expression may read besides the spec's own (not all in every context)
BUILTIN_NAMES = ("steps", "max_steps", "dt", "action")
_RESERVED = set(FUNCTIONS) | set(CONSTANTS) | set(BUILTIN_NAMES) | set(keyword.kwlist) | {"True", "False", "None"}


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
    # the MuJoCo model and what the generated code reads from it (docs/physics.md)
    physics: "phys.PhysicsPlan | None" = None
    _builders: dict[str, FunctionBuilder] = field(default_factory=dict, repr=False)
    #: compiled with the caller's consent to import the spec's ``dynamics.python`` (``compile_spec(trust_code=True)``)
    trust_code: bool = False
    _python_dynamics: Callable[..., Any] | None = field(default=None, repr=False)
    _render_plan: RenderPlan | None = field(default=None, repr=False)

    @property
    def spec(self) -> Spec:
        return self.loaded.spec

    def functions(self, random: RandomSource, simulation: Any = None) -> "CompiledFunctions":
        """Fresh callables bound to `random` (one set per env), and to the env's `simulation` for a physics spec."""
        self.check_code_consent()
        env = function_globals(bind_random(random))
        env["_python_dynamics"] = self._python_dynamics
        env["_random"] = random
        if self.physics is not None:
            if simulation is None:
                raise ValueError("a physics spec's functions need the env's simulation (Program.physics.simulation())")
            self.physics.bind(env, simulation)
        built = {key: b.build(env) for key, b in self._builders.items()}
        return CompiledFunctions(built["init"], built["step"], built["bind"], built.get("observe"))

    def check_code_consent(self) -> None:
        """Raise the SpecError, located at ``dynamics.python``, of a spec whose Python hook was not imported: it was
        compiled without ``trust_code=True``, and no env runs it (docs/security.md)."""
        refuse_untrusted_code(self.loaded, self._python_dynamics is not None)

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
            return BatchFunctions(
                vectorize(builders["step"], env), vectorize(builders["bind"], env), vectorize(builders["observe"], env)
            )
        return BatchFunctions(vectorize(self._builders["step"]), vectorize(self._builders["bind"]))

    def render_plan(self) -> RenderPlan:
        """What a renderer needs: the scene, the observation cameras, the settings and the binding targets (built once)."""
        if self._render_plan is None:
            self._render_plan = self._build_render_plan()
        return self._render_plan

    def _build_render_plan(self) -> RenderPlan:
        spec = self.spec
        return RenderPlan(
            scene=scene_plan(spec.scene),
            views=views_plan(spec.observation),
            single=spec.observation is None or spec.observation.cameras is None,
            settings=to_plan(spec.render),
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


def compile_spec(loaded: LoadedSpec, params: Mapping[str, Any] | None = None, *, trust_code: bool = False) -> Program:
    """Resolve and check every expression in `loaded`; raise SpecError listing all problems.

    A ``dynamics.python`` hook is imported (its module's code runs) only with `trust_code`; without it the reference's
    form is checked, nothing is imported, and making an env from the Program raises a SpecError saying so.
    """
    if not isinstance(trust_code, bool):  # a consent is True, not any value that happens to be truthy ("false")
        raise TypeError(f"trust_code must be True or False, got {trust_code!r}")
    return _Compiler(loaded, dict(params or {}), trust_code).run()


def _override_error(key: str, message: str) -> SpecError:
    """A bad ``make(params=...)`` override, located at the options rather than a spec line."""
    return SpecError([Diagnostic(OPTIONS_WHERE, None, None, f"params.{key}", message)])


class _Compiler(ActionsCompiler, BindingsCompiler, StepCompiler):
    def __init__(self, loaded: LoadedSpec, overrides: dict[str, Any], trust_code: bool = False):
        self.loaded = loaded
        self.trust_code = trust_code
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

    def expr(
        self, path: tuple, text: Any, names: Mapping[str, Type], *, expect: Type | None = None, random: bool = True
    ) -> Checked | None:
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
        sections = {
            ("params",): list(self.spec.params),
            ("dynamics", "let"): list(self.spec.dynamics.let),
            ("state",): list(self.spec.state),
        }
        for prefix, names in sections.items():
            if tuple(path[: len(prefix)]) == prefix and wanted in names:
                where = ".".join(prefix)
                if len(path) > len(prefix) and path[len(prefix)] == wanted:
                    return f"unknown name '{wanted}': '{wanted}' cannot be used in its own definition in {where} (cyclic definitions are not allowed)"
                return (
                    f"unknown name '{wanted}': '{wanted}' is defined later in {where}: an entry can only use the ones above it "
                    "(reorder them; cyclic definitions are not allowed)"
                )
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
            self.loaded,
            self.params,
            state_names,
            observed,
            input_names,
            discrete,
            continuous,
            outcomes,
            bindings,
            line_maps={k: b.line_map() for k, b in builders.items()},
            physics=self.plan,
            trust_code=self.trust_code,
            _builders=builders,
            _python_dynamics=python_dynamics,
        )

    # -- physics ---------------------------------------------------------------------------------

    def load_physics(self) -> None:
        """The MJCF model, its names in scope, its contacts and keyframe resolved; a problem is located at its field."""
        section = self.spec.physics
        if section is None:
            return
        try:
            model = phys.load(section, self.loaded.base_dir, self.spec.scene.max_image_pixels)
        except phys.PhysicsError as exc:
            self.error(("physics", "model"), str(exc))
            raise SpecError(in_file_order(self.problems)) from None
        geoms = {n: i for i, n in enumerate(model.names.ident["geom"])}
        contacts: dict[str, tuple[int, int]] = {}
        for key, pair in section.contacts.items():
            if key in model.names.values:
                self.error(
                    ("physics", "contacts", key), f"'{key}' is a name of the physics model: choose another", key=True
                )
            unknown = [(i, g) for i, g in enumerate(pair) if g not in geoms]
            for i, g in unknown:
                self.error(
                    ("physics", "contacts", key, i),
                    f"no geom '{g}' in the model" + did_you_mean(g, geoms).replace("names:", "geoms:"),
                )
            if not unknown:
                contacts[key] = (geoms[pair[0]], geoms[pair[1]])
        keyframe = None
        if section.reset.keyframe is not None:
            keys = {n: i for i, n in enumerate(model.names.ident["key"])}
            keyframe = keys.get(section.reset.keyframe)
            if keyframe is None:
                self.error(
                    ("physics", "reset", "keyframe"),
                    f"no keyframe '{section.reset.keyframe}' in the model"
                    + did_you_mean(section.reset.keyframe, keys).replace("names:", "keyframes:"),
                )
        if "dt" in self.spec.model_fields_set:
            self.error(
                ("dt",), "with physics, dt is the model's timestep times physics.frame_skip: leave 'dt' out", key=True
            )
        self.plan = phys.PhysicsPlan(model, section.frame_skip, keyframe, contacts, convention=section.convention)
        if self.spec.observation is not None or self.spec.render.view.camera:  # drawn: every geom must be drawable
            try:
                self.plan.scene = phys.physics_scene(model, section.draw_sites, section.look)
            except phys.PhysicsError as exc:
                self.error(("physics", "model"), str(exc))
        self.pnames = phys.scope(model, section.contacts)

    def physics_objects(self) -> dict[str, str]:
        """The objects the renderer makes of the model (drawn geoms, lights, cameras) by name, with their Blender types."""
        if self.plan is None or self.plan.scene is None:
            return {}
        scene = self.plan.scene
        return {
            **{g.name: "MESH" for g in scene.geoms},
            **{light.name: "LIGHT" for light in scene.lights},
            **{c.name: "CAMERA" for c in scene.cameras},
        }

    def physics_reads(
        self, fb: FunctionBuilder, key: str, at: int, used: set[str], exclude: Collection[str] = ()
    ) -> None:
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
            entries = [
                *model.qpos_names(),
                *model.qvel_names(),
                *(n for n in state_names if self.spec.state[n].observe),
            ]
        start, before = len(fb.body), set(self.used)
        self.used = set()
        values: list[ast.expr] = []
        for i, entry in enumerate(entries):
            path = ("physics", "observe", i) if self.spec.physics.observe is not None else ("physics",)
            checked = self.expr(path, entry, scope, expect=NUM)
            if checked:
                fb.assign_checked(f"_o{i}", path, checked)
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
            ("params", list(spec.params)),
            ("state", list(spec.state)),
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
                    index = next(
                        i for i, a in enumerate((spec.actions.discrete if spec.actions else None) or []) if n in a
                    )
                    path = ("actions", "discrete", index, n)
                if n in _RESERVED:
                    self.error(
                        path, f"'{n}' is a reserved name (a built-in, function or keyword): choose another", key=True
                    )
                elif n in seen and not (group == "actions.discrete" and seen[n] == group):
                    self.error(path, f"'{n}' is already defined in {seen[n]}", key=True)
                else:
                    seen[n] = group
        for group, names in groups:
            for n in names:
                path = ("actions", "discrete") if group == "actions.discrete" else tuple(group.split(".")) + (n,)
                if n in self.pnames and not (group.startswith("actions") and n.startswith("ctrl_")):
                    self.error(path, f"'{n}' is a name of the physics model: choose another", key=True)
                elif (
                    self.plan is not None
                    and group.startswith("actions")
                    and n.startswith("ctrl_")
                    and n not in self.pnames
                ):
                    controls = [f"ctrl_{a}" for a in self.plan.model.actuator_names()]
                    self.error(
                        path,
                        f"no actuator '{n[5:]}' in the model for '{n}'"
                        + did_you_mean(n, controls).replace("names:", "controls:"),
                        key=True,
                    )
        if "max_steps" in spec.outcomes:
            self.error(
                ("outcomes", "max_steps"),
                "'max_steps' is what info['outcome'] says when an episode reaches max_steps: choose another name",
                key=True,
            )
        moved = self.plan.model.mocap_names() if self.plan is not None else []  # a mocap pose is set there too
        for n in spec.dynamics.update:
            if n not in spec.state and n not in moved:
                self.error(
                    ("dynamics", "update", n),
                    f"'{n}' is not a state variable"
                    + (" or a mocap pose" if moved else "")
                    + did_you_mean(n, [*spec.state, *moved]).replace(
                        "names:", "state and mocap poses:" if moved else "state:"
                    ),
                    key=True,
                )

    def resolve_params(self) -> dict[str, float | bool]:
        params: dict[str, float | bool] = {}
        for key in self.overrides:
            if key not in self.spec.params:
                raise _override_error(key, f"unknown parameter override '{key}'" + did_you_mean(key, self.spec.params))
        raw = {**self.spec.params, **self.overrides}
        builtins = {
            "max_steps": float(self.spec.max_steps),
            "dt": float(self.plan.dt if self.plan is not None else self.spec.dt),
        }
        self.params = {}
        scope: dict[str, float | bool] = dict(builtins)  # grown in place: a copy per param is quadratic in their count
        for key, value in raw.items():
            if isinstance(value, bool):
                params[key] = scope[key] = value
            else:
                try:
                    checked = check(value, {}, constants=scope, allow_random=False)
                except ExpressionError as exc:
                    self.param_error(key, self.explain_order(("params", key), exc.message), column=exc.offset)
                    continue
                if checked.constant is None or isinstance(checked.constant, tuple):
                    self.param_error(key, "a parameter must be a number or a condition")
                    continue
                params[key] = scope[key] = checked.constant
        return {**builtins, **params}

    def param_error(self, key: str, message: str, *, column: int | None = None) -> None:
        """A bad param: blamed on the override when the value came from make(params=...), else on the spec's line.

        A bad override stops compiling at once: the params that use it would only repeat the problem.
        """
        if key in self.overrides:
            raise _override_error(key, f"{message} (in the override {self.overrides[key]!r})")
        self.error(("params", key), message, column=column)

    def resolve_python_dynamics(self) -> Callable[..., Any] | None:
        """The spec's Python hook: its reference checked by form, imported only with the caller's consent."""
        target = self.spec.dynamics.python
        if not target:
            return None
        if self.spec.dynamics.update or self.spec.dynamics.let:
            self.error(("dynamics", "python"), "'python' dynamics replace 'let' and 'update': give one or the other")
        problem = reference_problem(target)
        if problem is not None:
            self.error(("dynamics", "python"), problem)
            return None
        if not self.trust_code:
            return None  # not imported: Program.check_code_consent says why when an env is made
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
