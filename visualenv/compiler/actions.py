"""The compiler's part that turns a spec's ``actions`` into the action space and the step's inputs.

Mixed into the spec compiler (:func:`visualenv.compiler.program.compile_spec`), whose names in scope, errors and
expression checks it uses: ``spec``, ``plan``, ``pnames``, ``expr``.
"""

from __future__ import annotations

import ast
from typing import Any

from visualenv.expr import NUM, Type
from visualenv.expr.codegen import FunctionBuilder, Site, const, local, lower, name


class ActionsCompiler:
    """Resolves the action space (discrete choices, continuous inputs with bounds, or a physics spec's actuators) and
    writes the step's lines that set each input from the action."""

    spec: Any
    plan: Any
    pnames: dict[str, Type]
    expr: Any

    def resolve_actions(self) -> tuple[list[str], int | None, list[tuple[float, float]]]:
        actions = self.spec.actions
        # a physics spec's default: one Box dimension per actuator, in its ctrlrange (Gymnasium's action space)
        if actions is None:
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

    def step_discrete_inputs(
        self, fb: FunctionBuilder, scope: dict[str, Type], input_names: list[str], discrete: int
    ) -> None:
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
