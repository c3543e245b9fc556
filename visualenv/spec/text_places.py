"""Where each character of a multi-line string value is written in its file, so an error inside it names its line.

YAML folds a multi-line value (a ``>-`` block, a plain scalar continued on the next
line) and strips a ``|`` block's indentation; TOML trims a multi-line string's first
line break. Each changes only whitespace: the value's other characters are the
file's, in order, so matched one by one from where the value's text starts they give
each character's line and column. Where they do not match (an escape in a quoted
string), there is no map, and an error names the value's first line, as before.
"""

from __future__ import annotations

from typing import Any

from visualenv.source_map import Places


def places(value: str, text: str, start: int, line: int, column: int) -> Places | None:
    """Where each character of `value` is in `text`, read from index `start` (which is at `line`, `column`); None if
    the value's non-blank characters are not the text's, in order (whitespace in the value takes the previous place)."""
    out: list[tuple[int, int]] = []
    last = (line, column)
    i, size = start, len(text)
    for char in value:
        if char.isspace():
            out.append(last)
            continue
        while i < size and text[i] != char:
            if not text[i].isspace():
                return None
            line, column = (line + 1, 1) if text[i] == "\n" else (line, column + 1)
            i += 1
        if i >= size:
            return None
        out.append((line, column))
        i, column = i + 1, column + 1
        last = (line, column)
    return tuple(out)


def yaml_places(node: Any, value: str) -> Places | None:
    """The places of a YAML scalar's value (`node`: a yaml.ScalarNode composed from text, whose marks hold it)."""
    mark = node.start_mark
    text = mark.buffer
    if not isinstance(text, str):
        return None
    start, line, column = mark.index, mark.line + 1, mark.column + 1
    if node.style in ("|", ">"):  # the text starts on the line after the block's header (`>-`, a comment)
        newline = text.find("\n", start)
        if newline < 0:
            return None
        start, line, column = newline + 1, line + 1, 1
    elif node.style in ("'", '"'):
        start, column = start + 1, column + 1
    return places(value, text, start, line, column)


def toml_places(text: str, line: int, column: int, value: str) -> Places | None:
    """The places of a TOML multi-line string (``\"\"\"`` or ``'''``) whose opening quotes are at `line`, `column`."""
    lines = text.splitlines(keepends=True)
    if not 0 < line <= len(lines):
        return None
    start = sum(len(t) for t in lines[: line - 1]) + column - 1
    if text[start : start + 3] not in ('"""', "'''"):
        return None
    return places(value, text, start + 3, line, column + 3)
