"""A spec's trusted Python escape hatch (``dynamics.python: 'module:function'``), its answer checked every step."""

from __future__ import annotations

from typing import Any, Callable, Mapping

from visualenv.errors import did_you_mean


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
            raise ValueError(
                f"the function returned {type(out).__name__}, expected a dict of new state values (state: {', '.join(state_names)})"
            )
        unknown = [str(k) for k in out if k not in known]
        if unknown:
            raise ValueError(
                f"the function returned {', '.join(map(repr, unknown))}, which is not state"
                + did_you_mean(unknown[0], state_names).replace("names:", "state:")
            )
        new = {}
        for key, value in out.items():
            try:
                new[key] = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"the function returned {key}={value!r}, expected a number") from None
        return new

    return call
