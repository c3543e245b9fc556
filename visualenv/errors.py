"""Errors visualenv raises on purpose.

Every problem found in a spec becomes a :class:`Diagnostic` that knows the file,
line and column it refers to, and a :class:`SpecError` carries all the
diagnostics found in one pass, so a user fixes a file in one go instead of one
error at a time. The CLI prints them and exits with status 2; it never shows a
Python traceback for bad input.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Iterable, Sequence


@dataclass(frozen=True)
class Diagnostic:
    """One problem in a spec, located as precisely as the parser allows."""

    file: str
    line: int | None
    column: int | None
    path: str
    message: str

    def __str__(self) -> str:
        where = self.file
        if self.line is not None:
            where += f":{self.line}"
            if self.column is not None:
                where += f":{self.column}"
        field = f" {self.path}:" if self.path else ""
        return f"{where}:{field} {self.message}"


def in_file_order(diagnostics: Iterable[Diagnostic]) -> list[Diagnostic]:
    """Diagnostics sorted by line and column, as a reader meets them (unlocated ones first)."""
    return sorted(diagnostics, key=lambda d: (d.line or 0, d.column or 0))


class VisualEnvError(Exception):
    """Base class of the errors visualenv raises for its users."""


class SpecError(VisualEnvError):
    """A spec that cannot be loaded, validated or compiled (one or more problems)."""

    def __init__(self, diagnostics: Sequence[Diagnostic], notes: Sequence[str] = ()):
        self.diagnostics = list(diagnostics)
        #: lines shown after the diagnostics, such as Blender's own output when it failed to read a file
        self.notes = list(notes)
        super().__init__("\n".join([*(str(d) for d in self.diagnostics), *self.notes]))


class ExpressionError(VisualEnvError):
    """An expression that is not in the language; `offset` is a column in its text."""

    def __init__(self, message: str, offset: int = 0):
        self.message = message
        self.offset = offset
        super().__init__(message)


class RenderError(VisualEnvError):
    """The renderer could not build or render the scene."""


class StepError(VisualEnvError):
    """A runtime fault (NaN, division by zero, math domain) while stepping an env.

    A vector env's names the env it happened in (``env 3: ...``, index in :attr:`env`);
    :attr:`fault` is the message that env alone gives.
    """

    def __init__(self, message: str, env: int | None = None) -> None:
        self.fault = message
        self.env = env
        super().__init__(message if env is None else f"env {env}: {message}")

    def in_env(self, env: int) -> "StepError":
        """The same fault, as env `env` of a vector env reports it."""
        return StepError(self.fault, env)


class ConfigError(VisualEnvError):
    """A training setting the algorithm cannot take (an unknown hyperparameter, a malformed schedule)."""


class WorkerError(VisualEnvError):
    """A parallel env worker died or stopped answering."""


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """A hint naming the closest candidate, and all of them when there are few."""
    names = list(dict.fromkeys(candidates))
    close = difflib.get_close_matches(name, names, n=1, cutoff=0.6)
    hint = f" (did you mean '{close[0]}'?" if close else " ("
    listing = ", ".join(names[:30]) + (", ..." if len(names) > 30 else "")
    if close:
        return hint + (f" names: {listing})" if names else ")")
    return hint + (f"names: {listing})" if names else "no names are defined)")
