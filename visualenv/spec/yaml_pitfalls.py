"""YAML's traps, explained: what PyYAML (a YAML 1.1 reader) does with tabs, indentation, commas inside ``{...}``,
``4e2`` and ``yes``, and what to write instead.

:mod:`visualenv.spec.source` asks :func:`explain_syntax_error` for the message of a syntax error (PyYAML's own
words first, then what they mean for a spec) and reads the number and boolean rules here; the loader adds
:data:`~visualenv.source_map.COMMA_HINT` to every problem inside a ``{...}`` or ``[...]`` that YAML split at a comma. docs/spec.md's
"YAML pitfalls" table lists each trap; tests/spec/test_yaml_pitfalls.py feeds every row.
"""

from __future__ import annotations

import re

import yaml

#: a number with an exponent as YAML 1.2 writes it (``4e2``, ``1e-3``, ``2.5E+4``): YAML 1.1 reads ``4e2`` and ``1.0e5`` as text
EXPONENT_NUMBER = re.compile(r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)[eE][-+]?[0-9]+$")
#: the words YAML 1.1 reads as booleans and YAML 1.2 as text (``true``/``false`` mean the same in both)
YAML11_BOOLEANS = {"yes": True, "no": False, "on": True, "off": False}

TAB_HINT = "YAML indents with spaces only: replace the tab with spaces"
INDENT_RULE = (
    "the keys of one mapping, and the '-' items of one list, start in the same column, "
    "and what belongs to a key is indented further than the key (with spaces)"
)


def split_at_comma(text: str) -> bool:
    """Whether `text` looks like a piece of an expression that YAML split at a comma: its brackets do not pair up."""
    depth = 0
    for char in text:
        depth += char in "(["
        depth -= char in ")]"
        if depth < 0:
            return True
    return depth != 0


def opens_and_closes(text: str) -> tuple[bool, bool]:
    """(leaves a bracket open, closes one it did not open): the two halves of an expression cut at a comma."""
    depth = lowest = 0
    for char in text:
        depth += char in "(["
        depth -= char in ")]"
        lowest = min(lowest, depth)
    return depth > lowest, lowest < 0


def boolean_word(value: str) -> str:
    """Why a plain ``yes``/``no``/``on``/``off`` value is refused, and what to write."""
    meaning = str(YAML11_BOOLEANS[value.lower()]).lower()
    return f"YAML 1.1 reads '{value}' as the boolean {meaning}, YAML 1.2 as text: write {meaning} (or \"{value}\" in quotes for the text)"


def explain_syntax_error(exc: yaml.MarkedYAMLError, text: str) -> tuple[int | None, int | None, str]:
    """(line, column, message) of a YAML syntax error: PyYAML's words, then what is wrong in spec terms.

    The position is the line at fault: where an unclosed ``{`` or a key without ``:`` is, not the line after it
    where PyYAML noticed.
    """
    lines = text.splitlines()
    mark = exc.problem_mark or exc.context_mark
    problem = exc.problem or exc.context or "invalid YAML"
    context = exc.context_mark
    if context is not None and exc.problem and "end of stream" in exc.problem:
        mark = context  # an unclosed quote or bracket: point at where it opened
    message = f"YAML syntax error: {problem}" + (f" ({exc.context})" if exc.context and exc.problem else "")
    hint = ""
    if "'\\t'" in problem or "tab" in problem:
        hint = TAB_HINT
    elif mark is not None and problem == "expected <block end>, but found '-'":
        hint = (
            f"line {mark.line + 1} starts a '-' list item among the keys of a mapping: a list goes under a key of its own "
            "('key:', then its '- ' items on the lines below)"
        )
    elif mark is not None and (
        problem.startswith("expected <block end>") or problem.startswith("did not find expected")
    ):
        hint = _indentation(mark.line, lines)
    elif mark is not None and problem == "mapping values are not allowed here":
        hint = _colon_in_value(mark.line, lines)
    elif context is not None and problem == "could not find expected ':'":
        mark = context
        key = lines[context.line].strip() if context.line < len(lines) else ""
        hint = f"'{key}' has no ':' after it: write 'key: value' (a space after ':'), or indent the line as part of the value above"
    elif context is not None and mark is not None and re.match(r"expected ',' or '[}\]]'", problem):
        bracket = "{" if "}" in problem[:20] else "["
        if context.line != mark.line:
            hint = (
                f"the '{bracket}' on line {context.line + 1} is not closed on its line (YAML went on to line {mark.line + 1}): "
                f"close it, or quote a value in it that holds ': ' or ','"
            )
            mark = context
        else:
            hint = f"a value inside {bracket}...{'}' if bracket == '{' else ']'} holds ': ' or ','; quote it, e.g. {{when: \"x > 0\"}}"
    if hint:
        message += f": {hint}"
    return (mark.line + 1 if mark else None), (mark.column + 1 if mark else None), message


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


def _line_above(index: int, lines: list[str]) -> int | None:
    """The nearest line above `index` that holds something (not blank, not only a comment)."""
    for j in range(min(index, len(lines)) - 1, -1, -1):
        stripped = lines[j].strip()
        if stripped and not stripped.startswith("#"):
            return j
    return None


def _spaces(n: int) -> str:
    return f"{n} space" + ("" if n == 1 else "s")


def _indentation(index: int, lines: list[str]) -> str:
    """Bad indentation at line `index` (0-based): how far it and the line above are indented, and the rule."""
    above = _line_above(index, lines)
    if index >= len(lines) or above is None:
        return f"bad indentation: {INDENT_RULE}"
    return (
        f"bad indentation: line {index + 1} is indented by {_spaces(_indent(lines[index]))}, line {above + 1} above it by "
        f"{_spaces(_indent(lines[above]))}; {INDENT_RULE}"
    )


def _colon_in_value(index: int, lines: list[str]) -> str:
    """'mapping values are not allowed here': a key indented under a line that already has a value, or ': ' inside a value."""
    above = _line_above(index, lines)
    if index < len(lines) and above is not None and _indent(lines[index]) > _indent(lines[above]):
        head, _, value = lines[above].partition(":")
        if value.split("#", 1)[0].strip():
            return (
                f"bad indentation: line {index + 1} is indented under line {above + 1}, which already has a value "
                f"('{lines[above].strip()}'); indent it like the keys beside it, or give '{head.strip()}' no value on its line"
            )
    return "a value that holds ': ' must be quoted, e.g. description: \"note: ...\" (or the line is indented under a value)"
