"""A spec's Python escape hatch (``dynamics.python: 'module:function'``): its reference checked without importing it,
imported only with the caller's consent (``trust_code``), its answer checked every step."""

from __future__ import annotations

import keyword
from typing import Any, Callable, Mapping

from visualenv.errors import SpecError, did_you_mean
from visualenv.spec.loader import LoadedSpec


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


def reference_problem(target: str) -> str | None:
    """What is wrong with the form of a ``'module:function'`` reference (None when it is well formed), found without
    importing anything: the module a dotted path of Python identifiers, the function one identifier, none a keyword."""
    module_name, sep, func_name = target.partition(":")
    if not sep or ":" in func_name:
        return f"expected 'module:function' (one ':'), got {target!r}"
    for part in [*module_name.split("."), func_name]:
        if not part:
            return f"{target!r} has an empty name (expected 'module:function', e.g. 'mypackage.dynamics:step')"
        if not part.isidentifier():
            return f"{part!r} in {target!r} is not a Python identifier (expected 'module:function', e.g. 'mypackage.dynamics:step')"
        if keyword.iskeyword(part):
            return f"{part!r} in {target!r} is a Python keyword, not a name a module or function can have"
    return None


def untrusted_message(target: str) -> str:
    """Why a spec's hook was not imported, what importing it would do and how to consent (docs/security.md)."""
    module_name, _, func_name = target.partition(":")
    return (
        f"this spec runs Python code: making its env imports the module '{module_name}' (which runs that module's "
        f"code) and calls its '{func_name}' every step. visualenv imports it only with your consent, given when you "
        "trust the spec's author as you would a Python script: pass --trust-code on the command line (Python: "
        "trust_code=True to visualenv.make, gymnasium.make, visualenv.register, make_vec or compile_spec) "
        "(docs/security.md)"
    )


def refuse_untrusted_code(loaded: LoadedSpec, trust_code: bool) -> None:
    """Raise the SpecError, located at ``dynamics.python``, of a spec with a Python hook made without consent: checked
    before anything is built or written (a run folder), without compiling the spec."""
    target = loaded.spec.dynamics.python
    if target and not trust_code:
        raise SpecError([loaded.source.diagnostic(("dynamics", "python"), untrusted_message(target))])
