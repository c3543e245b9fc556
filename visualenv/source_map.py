"""Where each value of a loaded spec is written: a table from field paths to positions, and located diagnostics.

The spec's reader fills a :class:`SourceMap` (:mod:`visualenv.spec.source`); the compiler and the renderer
locate what they refuse with it. It is plain data at the foundation, so a layer that must not import the spec
(render) still words an error as the spec's loader does.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from visualenv.errors import Diagnostic

#: (line, column) of each character of a multi-line value, both 1-based (:mod:`visualenv.spec.text_places`)
Places = tuple[tuple[int, int], ...]

#: what an expression cut in two at a comma of a YAML flow mapping or list needs
COMMA_HINT = {
    "{": 'an expression with a comma inside {...} was split by YAML; quote it, e.g. {init: "uniform(-1, 1)"}',
    "[": 'an expression with a comma inside [...] was split by YAML; quote it, e.g. ["clip(x, -1, 1)", 0, 0]',
}


#: where a value sits in the spec: keys and list indexes from the top
SpecPath = tuple[str | int, ...]


@dataclass
class Position:
    line: int
    column: int
    #: for single-line string scalars: how many characters precede the text
    #: (1 for a quoted scalar), so an expression column can be added to it.
    text_offset: int | None = None
    #: for multi-line strings: the line and column of each of the value's characters (text_places.py)
    places: Places | None = None


@dataclass
class SourceMap:
    """Where each value (and each mapping key) of a loaded document is written."""

    file: str
    values: dict[SpecPath, Position] = field(default_factory=dict)
    keys: dict[SpecPath, Position] = field(default_factory=dict)
    #: YAML flow collections (``{...}`` or ``[...]``, by their bracket) that a comma split in the middle of an expression
    split: dict[SpecPath, str] = field(default_factory=dict)

    def locate(self, path: SpecPath, *, key: bool = False) -> Position | None:
        """The position of `path`, or of its closest ancestor that has one."""
        path = tuple(path)
        if key and path in self.keys:
            return self.keys[path]
        while path:
            if path in self.values:
                return self.values[path]
            path = path[:-1]
        return self.values.get(())

    def diagnostic(
        self, path: SpecPath, message: str, *, key: bool = False, column_offset: int | None = None
    ) -> Diagnostic:
        pos = self.locate(path, key=key)
        line = pos.line if pos else None
        column = pos.column if pos else None
        if pos and column_offset is not None and pos.text_offset is not None and tuple(path) in self.values:
            column = pos.column + pos.text_offset + column_offset
        # a multi-line value: its own line
        elif pos and column_offset is not None and pos.places and tuple(path) in self.values:
            line, column = pos.places[min(max(column_offset, 0), len(pos.places) - 1)]
        return Diagnostic(self.file, line, column, format_path(path), self._with_comma_hint(tuple(path), message))

    def _with_comma_hint(self, path: SpecPath, message: str) -> str:
        """Every problem inside a flow collection that YAML split at a comma says so: it is the likely cause."""
        for i in range(len(path), -1, -1):
            bracket = self.split.get(path[:i])
            if bracket is not None:
                hint = COMMA_HINT[bracket]
                return message if hint in message else f"{message} ({hint})"
        return message


def format_path(path: SpecPath) -> str:
    """`('state', 'theta', 'init')` -> `state.theta.init`; list indexes as `[0]`."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out
