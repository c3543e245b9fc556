"""Runtime faults of a compiled spec, reported as located spec errors.

The generated init, step and bind functions run spec expressions as plain
Python arithmetic. A fault shows in one of two ways: an exception raised inside
the generated code (a division by zero, a math domain error), or a value found
after the function returned (NaN, an infinity, a number too large for the
float32 observation). The user must see neither as a traceback into generated
code: :class:`FaultDiagnosis` turns both into a :class:`~visualenv.errors.StepError`
that names the spec file and line, the expression and the values it read,
asking the program's line maps where each value came from. It lives apart from
the env so that the env's step reads as the loop it is.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from visualenv.compiler.program import Program
from visualenv.errors import StepError
from visualenv.expr.codegen import Site

#: the largest magnitude the float32 state-only observation holds: a finite state past it would be observed as inf
OBSERVATION_LIMIT = float(np.finfo(np.float32).max)
#: messages clearer than Python's own for the exceptions generated code raises
_MESSAGES: dict[type, str] = {ZeroDivisionError: "division by zero", OverflowError: "numeric overflow"}


class FaultDiagnosis:
    """Finds and describes the runtime faults of one program; every fault becomes a located StepError."""

    def __init__(self, program: Program) -> None:
        self.program = program
        self._observed = program.observed

    def raised(self, function: str, exc: BaseException, values: dict[str, Any], steps: int) -> StepError:
        """An exception raised inside the generated ``function`` (init, step or bind), named by the statement that raised it."""
        site = self.program.line_maps[function].site_in(exc.__traceback__)
        return self.describe(site, _MESSAGES.get(type(exc), str(exc)), values, steps)

    def check_reset(self, state: tuple, steps: int) -> None:
        """A state variable that is not finite at reset (e.g. init: inf, or a draw such as normal(0, inf))."""
        names = self.program.state_names
        for key, value in zip(names, state):
            if not math.isfinite(value):
                site = self.program.line_maps["init"].find(f"state.{key}.init")
                raise self.describe(site, f"state '{key}' is {value} at reset", dict(zip(names, state)), steps)

    def check_step(self, state: tuple, reward: float, values: dict[str, Any], steps: int) -> None:
        """A state variable or the reward that became NaN or infinite in a step, named by its update."""
        lines = self.program.line_maps["step"]
        for name, value in zip(self.program.state_names, state):
            if not math.isfinite(value):
                raise self.describe(
                    lines.find(f"dynamics.update.{name}"), f"state '{name}' became {value}", values, steps
                )
        if not math.isfinite(reward):
            raise self.describe(lines.find("reward"), f"the reward became {reward}", values, steps)

    def check_bindings(self, bound: tuple, values: dict[str, Any], steps: int) -> None:
        """An actor binding that became NaN or infinite (Blender would silently draw nothing or garbage)."""
        for i, value in enumerate(bound):
            if not math.isfinite(value):
                raise self.describe(self._binding_site(i), f"a binding became {value}", values, steps)

    def check_observable(self, state: tuple, what: str, values: dict[str, Any], steps: int) -> None:
        """A finite state can still overflow the float32 observation (it would read inf); ``what`` formats the site's name."""
        for i in self._observed:
            if not -OBSERVATION_LIMIT <= state[i] <= OBSERVATION_LIMIT:
                name = self.program.state_names[i]
                function = "init" if what.startswith("state.") else "step"
                site = self.program.line_maps[function].find(what.format(name))
                raise self.describe(
                    site, f"state '{name}' = {state[i]!r} is too large for the float32 observation", values, steps
                )

    def describe(self, site: Site | None, message: str, values: dict[str, Any], steps: int) -> StepError:
        """The error for a fault at ``site``: its file:line and expression, the message, and the values the expression read."""
        where = ""
        if site is not None:
            path = tuple(int(p) if p.isdigit() else p for p in site.what.split("."))
            loaded = self.program.loaded
            pos = loaded.source.locate(path)
            line = f"{loaded.file}:{pos.line}" if pos else loaded.file
            where = f"{line}: {site.what} = {site.text!r}: "
            relevant = {k: v for k, v in values.items() if k in site.names} or values
        else:
            relevant = values
        shown = ", ".join(f"{k}={v!r}" for k, v in relevant.items())
        return StepError(f"{where}{message} (step {steps}; values: {shown}){self._action_note(values)}")

    def _action_note(self, values: dict[str, Any]) -> str:
        """A continuous action that is not finite is the likely cause (a policy that diverged): named, input by input."""
        action = values.get("action")
        if self.program.discrete is not None or not isinstance(action, tuple):
            return ""
        bad = [f"{n}={v!r}" for n, v in zip(self.program.input_names, action) if not math.isfinite(v)]
        if not bad:
            return ""
        return f"; caused by the action, which is not finite: {', '.join(bad)} (action={list(action)!r})"

    def _binding_site(self, index: int) -> Site | None:
        """The site of the actor binding that yields value ``index`` of bind()."""
        for target in self.program.bindings:
            if index < target.size:
                return self.program.line_maps["bind"].find(f"actors.{target.object}.{target.property}")
            index -= target.size
        return None
