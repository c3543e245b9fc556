"""The keys and sliders of a spec's actions, as the viewer's page lists them and its session reads them.

Discrete actions: the digit keys 0-9 pick actions 0-9. The arrow keys go to the actions that move one input each
way: an action whose only non-zero input is a number, a param or a negated one (``force: -force_mag``) has that
input's direction; the first such input takes the left and right arrows, the second down and up. So CartPole's
push left and right are the left and right arrows and Hover2D's four pulses are the four arrows. A sign that
cannot be read this way gets no arrow (spec expressions are never run here).

Continuous actions: a slider per input (from its low to its high, starting at 0 or the nearest bound), and while an
arrow is held, the first input at its low (left) or high (right) end, the second at its low (down) or high (up) end.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from visualenv.compiler.program import Program

ARROWS = (("ArrowLeft", "ArrowRight"), ("ArrowDown", "ArrowUp"))  # (negative, positive) of the first and second input
ARROW_NAMES = {"ArrowLeft": "left", "ArrowRight": "right", "ArrowDown": "down", "ArrowUp": "up"}


@dataclass
class Controls:
    """What the keys and sliders do for one program."""

    #: discrete actions: key (a KeyboardEvent.key) -> action index
    keys: dict[str, int] = field(default_factory=dict)
    #: continuous actions: key -> (input index, the value it holds the input at)
    holds: dict[str, tuple[int, float]] = field(default_factory=dict)
    #: continuous actions: each input's (name, low, high)
    inputs: list[tuple[str, float, float]] = field(default_factory=list)
    #: the page's legend: {"keys": [...], "text": ...} per action or held input
    legend: list[dict[str, Any]] = field(default_factory=list)
    #: action index -> a short description for the page ("1: force = force_mag")
    labels: dict[int, str] = field(default_factory=dict)

    @property
    def discrete(self) -> bool:
        return not self.inputs

    def slider_start(self) -> list[float]:
        """Each continuous input's starting value: 0, or the bound nearest to it."""
        return [float(np.clip(0.0, low, high)) for _, low, high in self.inputs]

    def page(self, values: list[float]) -> dict[str, Any]:
        """The controls as the page draws them (the sliders at `values`)."""
        sliders = [
            {"name": name, "low": low, "high": high, "value": value}
            for (name, low, high), value in zip(self.inputs, values)
        ]
        return {"keys": self.legend, "sliders": sliders}


def controls_for(program: Program) -> Controls:
    """The keys (and sliders) of `program`'s action space."""
    if program.discrete is not None:
        return _discrete(program)
    return _continuous(program)


def _discrete(program: Program) -> Controls:
    actions = list(program.spec.actions.discrete or []) if program.spec.actions is not None else []
    controls = Controls()
    arrows = _arrows(actions, program.input_names, program.params)
    for index, action in enumerate(actions):
        text = ", ".join(f"{name} = {value}" for name, value in action.items()) or "no input"
        keys = [key for key, target in arrows.items() if target == index] + ([str(index)] if index < 10 else [])
        controls.keys.update((key, index) for key in keys)
        controls.labels[index] = f"{index}: {text}"
        if keys:
            controls.legend.append({"keys": keys, "text": f"action {index}: {text}"})
    return controls


def _arrows(actions: Sequence[Mapping[str, Any]], inputs: list[str], params: Mapping[str, Any]) -> dict[str, int]:
    """Arrow key -> action index, for the actions that move one input one way (see the module's docstring)."""
    moves: dict[tuple[str, int], list[int]] = {}
    for index, action in enumerate(actions):
        signs = {name: _sign(value, params) for name, value in action.items()}
        if any(sign is None for sign in signs.values()):
            continue
        moving = [(name, sign) for name, sign in signs.items() if sign]
        if len(moving) == 1:
            moves.setdefault(moving[0], []).append(index)
    axes = [name for name in inputs if any(name == moved for moved, _ in moves)][: len(ARROWS)]
    arrows = {}
    for (negative, positive), name in zip(ARROWS, axes):
        for key, sign in ((negative, -1), (positive, 1)):
            owners = moves.get((name, sign), [])
            if len(owners) == 1:
                arrows[key] = owners[0]
    return arrows


def _sign(value: Any, params: Mapping[str, Any]) -> int | None:
    """The sign of an action's value when it is a number, a param, or one of those negated; None otherwise."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return int(np.sign(value))
    if not isinstance(value, str):
        return None
    text, negate = value.strip(), 1
    while text.startswith("-"):
        text, negate = text[1:].strip(), -negate
    try:
        number = float(text)
    except ValueError:
        given = params.get(text)
        if isinstance(given, bool) or not isinstance(given, (int, float)):
            return None
        number = float(given)
    return negate * int(np.sign(number))


def _continuous(program: Program) -> Controls:
    controls = Controls(
        inputs=[(name, float(low), float(high)) for name, (low, high) in zip(program.input_names, program.continuous)]
    )
    for index, ((negative, positive), (name, low, high)) in enumerate(zip(ARROWS, controls.inputs)):
        controls.holds[negative] = (index, low)
        controls.holds[positive] = (index, high)
        controls.legend.append({"keys": [negative, positive], "text": f"{name} at {low:g} / {high:g} while held"})
    return controls
