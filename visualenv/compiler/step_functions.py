"""The compiler's part that generates ``init()`` and ``step()``: state inits, derived values, the simultaneous update,
the reward and the outcomes, as Python code checked by :mod:`visualenv.expr`.

Mixed into the spec compiler (:func:`visualenv.compiler.program.compile_spec`), whose names in scope, errors and
expression checks it uses: ``spec``, ``pnames``, ``params``, ``used``, ``plan`` (a physics spec's), ``error``, ``expr``,
``build_reset``, ``physics_reads`` and the action inputs' ``step_discrete_inputs`` / ``step_continuous_inputs``.
"""

from __future__ import annotations

import ast
from typing import Any

from visualenv.compiler import physics as phys
from visualenv.expr import BOOL, NUM, Type
from visualenv.expr.codegen import FunctionBuilder, Site, const, local, lower, name, tuple_of


class StepCompiler:
    """Generates the init and step functions of a spec's program."""

    spec: Any
    pnames: dict[str, Type]
    params: dict[str, Any]
    used: set[str]
    plan: Any
    updated: list[str]
    error: Any
    expr: Any
    build_reset: Any
    physics_reads: Any
    step_discrete_inputs: Any
    step_continuous_inputs: Any

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
                fb.assign_checked(local(n), path, checked)
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
        # the model's values before the step, for let and update; then the step; then the values after it
        if self.plan is not None:
            self.physics_reads(fb, "before", start, self.used, set(state_names) | set(input_names))
            fb.add(
                phys.advance_statement(self.plan),
                Site("physics", f"{self.spec.physics.model if self.spec.physics else ''}: the MuJoCo step"),
            )
            self.commit_update(fb)
            after_at = len(fb.body)
        self.used |= before
        fb.assign(local("steps"), ast.BinOp(name("_steps"), ast.Add(), const(1)))
        before_reward = set(self.used)
        self.used = set()
        # reward and outcomes read the new state
        checked = self.expr(("reward",), self.spec.reward, scope, expect=NUM)
        fb.assign(
            "_reward",
            lower(checked.tree) if checked else const(0.0),
            Site("reward", checked.text if checked else "", tuple(sorted(checked.names)) if checked else ()),
        )
        self.step_outcomes(fb, scope)
        if self.plan is not None:
            self.physics_reads(
                fb, "after", after_at, self.used, set(state_names) | set(input_names) | set(self.spec.dynamics.let)
            )
        self.used |= before_reward
        fb.returns(
            tuple_of(
                [tuple_of([name(local(n)) for n in state_names]), name("_reward"), name("_outcome"), name("_fired")]
            )
        )
        return fb

    def step_let(self, fb: FunctionBuilder, scope: dict[str, Type]) -> None:
        """Derived quantities, in order: each may use the ones before it."""
        for n, value in self.spec.dynamics.let.items():
            path = ("dynamics", "let", n)
            checked = self.expr(path, value, scope, expect=NUM)
            if checked:
                fb.assign_checked(local(n), path, checked)
            scope[n] = NUM

    def step_update(self, fb: FunctionBuilder, scope: dict[str, Type], commit: bool = True) -> None:
        """The simultaneous update: every right-hand side reads the old state, then all are assigned (``commit``; else by commit_update)."""
        spec = self.spec
        new_names = []
        for n, value in spec.dynamics.update.items():
            # a mocap pose (check_names refused the rest) is set in the MuJoCo step
            if n not in spec.state and n not in self.pnames:
                continue
            path = ("dynamics", "update", n)
            checked = self.expr(path, value, scope, expect=NUM)
            if checked:
                fb.assign_checked("_new_" + n, path, checked)
                new_names.append(n)
        self.updated = [n for n in new_names if n in spec.state]
        if self.plan is not None:
            self.plan.moved = [n for n in new_names if n not in spec.state]
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
                self.error(
                    ("outcomes", rule_name, "when"), "this condition is always false: the outcome can never happen"
                )
            add_reward = ast.AugAssign(ast.Name("_reward", ast.Store()), ast.Add(), lower(reward.tree))
            set_outcome = ast.Assign([ast.Name("_outcome", ast.Store())], const(index))
            if rule.end == "none":
                bit = milestone_bits[rule_name]
                not_fired = ast.Compare(ast.BinOp(name("_fired"), ast.BitAnd(), const(bit)), [ast.Eq()], [const(0)])
                mark = ast.AugAssign(ast.Name("_fired", ast.Store()), ast.BitOr(), const(bit))
                milestones.insert(
                    0, ast.If(ast.BoolOp(ast.And(), [not_fired, lower(when.tree)]), [add_reward, mark], [])
                )
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
        call = ast.Call(
            name("_python_dynamics"),
            [
                as_dict(state_names),
                as_dict(input_names),
                params,
                ast.Attribute(name("_random"), "generator", ast.Load()),
            ],
            [],
        )
        fb.assign("_py", call, Site("dynamics.python", self.spec.dynamics.python or ""))
        for n in state_names:
            get = ast.Call(ast.Attribute(name("_py"), "get", ast.Load()), [const(n), name(local(n))], [])
            fb.assign(local(n), get, Site("dynamics.python", f"the value returned for '{n}'"))
