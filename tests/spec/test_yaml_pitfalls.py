"""YAML's traps (issue 40): every row of docs/spec.md's "YAML pitfalls" table, fed as a user writes it.

Each case is a whole spec with one mistake; every message it gives must name the line at fault and say what
to write. The docs table and these cases are kept equal by a test.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest

from visualenv.compiler import compile_spec
from visualenv.errors import SpecError
from visualenv.spec.loader import load_spec_text

DOCS = Path(__file__).resolve().parents[2] / "docs" / "spec.md"

STATE = "state:\n  x: {init: 0}\n"
ACTIONS = "actions:\n  discrete: [{u: -1}, {u: 1}]\n"
BASE = "id: T-v0\n" + STATE + ACTIONS
CUBE = "id: T-v0\nscene:\n  objects:\n    Box: {primitive: cube}\n" + STATE + ACTIONS


@dataclass(frozen=True)
class Pitfall:
    name: str  # the first column of the docs table
    text: str
    at: str  # "line:column" of every message
    says: tuple[str, ...]  # pieces of every message


PITFALLS = [
    Pitfall(
        "tab",
        "id: T-v0\nstate:\n\tx: {init: 0}\n" + ACTIONS,
        "3:1",
        (
            "found character '\\t' that cannot start any token",
            "YAML indents with spaces only: replace the tab with spaces",
        ),
    ),
    Pitfall(
        "indentation",
        "id: T-v0\nstate:\n  x: {init: 0}\n   y: {init: 1}\n" + ACTIONS,
        "4:4",
        (
            "expected <block end>",
            "bad indentation: line 4 is indented by 3 spaces, line 3 above it by 2 spaces",
            "the keys of one mapping, and the '-' items of one list, start in the same column",
        ),
    ),
    Pitfall(
        "key under a value",
        BASE + "max_steps: 4\n  dt: 1\n",
        "7:5",
        (
            "mapping values are not allowed here",
            "line 7 is indented under line 6, which already has a value ('max_steps: 4')",
        ),
    ),
    Pitfall(
        "list among keys",
        "id: T-v0\nstate:\n  x: {init: 0}\n  - y\n" + ACTIONS,
        "4:3",
        (
            "but found '-'",
            "line 4 starts a '-' list item among the keys of a mapping: a list goes under a key of its own",
        ),
    ),
    Pitfall(
        "too little indented",
        "id: T-v0\nstate:\n  x:\n    init: 0\n  observe: true\n" + ACTIONS,
        "5:12",
        (
            "state.observe: expected a mapping, got a boolean True",
            "'observe' is a field of each entry of 'state': is it indented too little",
        ),
    ),
    Pitfall(
        "too far indented",
        BASE + "dynamics:\n  update: {x: x + u}\n  max_steps: 40\n",
        "8:3",
        (
            "dynamics.max_steps: unknown key 'max_steps'",
            "'max_steps' belongs to the top level: is it indented too far?",
        ),
    ),
    Pitfall(
        "comma in `{...}`",
        "id: T-v0\nstate:\n  x: {init: uniform(-1, 1)}\n" + ACTIONS,
        "3:25",
        (
            "unknown key '1)'",
            'an expression with a comma inside {...} was split by YAML; quote it, e.g. {init: "uniform(-1, 1)"}',
        ),
    ),
    Pitfall(
        "comma in `[...]`",
        CUBE + "actors:\n  Box: {location: [clip(x, 0, 1), 0, 0]}\n",
        "10:19",
        (
            "actors.Box.location: expected exactly 3 values, got 5",
            "an expression with a comma inside [...] was split by YAML; quote it",
        ),
    ),
    Pitfall(
        "colon in a value",
        "id: T-v0\ndescription: note: this\n" + STATE + ACTIONS,
        "2:18",
        ("mapping values are not allowed here", "a value that holds ': ' must be quoted"),
    ),
    Pitfall(
        "key without colon",
        "id: T-v0\nstate\n  x: {init: 0}\n" + ACTIONS,
        "2:1",
        ("could not find expected ':'", "'state' has no ':' after it"),
    ),
    Pitfall(
        "unclosed `{`",
        "id: T-v0\nstate:\n  x: {init: 0\n" + ACTIONS,
        "3:6",
        ("expected ',' or '}'", "the '{' on line 3 is not closed on its line (YAML went on to line 4)"),
    ),
    Pitfall(
        "exponent",
        BASE + "max_steps: 4e2\n",
        "6:12",
        ("max_steps: expected an integer, got a number 400.0", "without a decimal point or exponent: 400"),
    ),
    Pitfall("base 60", BASE + "max_steps: 1:30\n", "6:12", ("got text '1:30'", "base-60 number")),
    Pitfall(
        "yes, no, on, off",
        "id: T-v0\nstate:\n  x: {init: 0, observe: yes}\n" + ACTIONS,
        "3:25",
        ("state.x.observe: YAML 1.1 reads 'yes' as the boolean true, YAML 1.2 as text: write true",),
    ),
    Pitfall(
        "boolean key",
        "id: T-v0\nstate:\n  on: {init: 0}\n" + ACTIONS,
        "3:3",
        ("YAML 1.1 reads the key 'on' as the boolean true: quote it",),
    ),
    Pitfall(
        "duplicate key",
        BASE + "max_steps: 3\nmax_steps: 4\n",
        "7:1",
        ("duplicate key 'max_steps' (first defined on line 6)",),
    ),
]


def _messages(text: str) -> list[str]:
    """Every message a spec gets, loaded and compiled, as the CLI prints them."""
    try:
        compile_spec(load_spec_text(text, "spec.yaml"))
    except SpecError as exc:
        return [str(d) for d in exc.diagnostics]
    return []


@pytest.mark.parametrize("pitfall", PITFALLS, ids=lambda p: p.name)
def test_a_yaml_pitfall_is_located_and_explained(pitfall: Pitfall):
    messages = _messages(pitfall.text)
    assert messages, "accepted"
    assert messages[0].startswith(f"spec.yaml:{pitfall.at}:"), messages
    for message in messages:
        for piece in pitfall.says:
            assert piece in message, f"{piece!r} not in {message!r}"


def test_every_message_of_a_split_mapping_has_the_quoting_hint():
    """The issue's case: four pieces of two expressions, and every message says to quote."""
    text = (
        "id: T-v0\nparams: {dock_radius: 1, tx: 1, ty: 1}\nstate:\n  x: {init: 0}\n  y: {init: 0}\n  vx: {init: 0}\n  vy: {init: 0}\n"
        + ACTIONS
        + "outcomes:\n  docked: {when: hypot(x - tx, y - ty) <= dock_radius and hypot(vx, vy) < 0.2, reward: 1}\n"
    )
    messages = _messages(text)
    assert len(messages) == 2 and all("comma inside {...} was split by YAML; quote it" in m for m in messages), messages
    assert messages[0].startswith("spec.yaml:11:32: outcomes.docked.y - ty) <= dock_radius and hypot(vx: unknown key")
    discrete = _messages("id: T-v0\n" + STATE + "actions:\n  discrete: [{u: clip(x, 0, 1)}]\n")
    assert len(discrete) == 2 and all("comma inside {...} was split by YAML" in m for m in discrete), discrete


@pytest.mark.parametrize(
    "written, value", [("1e-3", 0.001), ("4e2", 400.0), ("2.5E+4", 25000.0), ("1.0e5", 100000.0), (".5e1", 5.0)]
)
def test_a_number_with_an_exponent_is_a_number_as_in_yaml_1_2(written: str, value: float):
    loaded = load_spec_text(BASE + f"dt: {written}\nparams: {{k: {written}}}\n", "spec.yaml")
    assert loaded.spec.dt == value and loaded.spec.params["k"] == value
    assert (
        load_spec_text(BASE + f"params: {{k: '{written}'}}\n", "spec.yaml").spec.params["k"] == written
    )  # quoted: text


@pytest.mark.parametrize("word", ["yes", "no", "on", "off", "Yes", "OFF"])
def test_a_yaml_11_boolean_word_is_refused_and_true_or_quoted_text_accepted(word: str):
    meaning = "true" if word.lower() in ("yes", "on") else "false"
    messages = _messages(CUBE + f"actors:\n  Box: {{visible: {word}}}\n")
    assert (
        len(messages) == 1
        and f"YAML 1.1 reads '{word}' as the boolean {meaning}, YAML 1.2 as text: write {meaning}" in messages[0]
    )
    assert _messages(CUBE + f"actors:\n  Box: {{visible: {meaning}}}\n") == []
    assert load_spec_text(BASE + f'description: "{word}"\n', "spec.yaml").spec.description == word


def test_the_docs_table_lists_exactly_these_pitfalls():
    text = DOCS.read_text(encoding="utf-8")
    section = text.split("## YAML pitfalls", 1)[1].split("\n## ", 1)[0]
    rows = [
        line.split("|")[1].strip()
        for line in section.splitlines()
        if line.startswith("| ") and not line.startswith(("| pitfall", "| ---"))
    ]
    assert rows == [p.name for p in PITFALLS]
    assert re.search(r"\[YAML pitfalls\]\(#yaml-pitfalls\)", text)


def test_a_bracket_left_out_is_not_blamed_on_a_comma():
    messages = _messages("id: T-v0\nstate:\n  x: {init: uniform(-1 1}\n" + ACTIONS)
    assert len(messages) == 1 and "'(' was never closed" in messages[0] and "comma" not in messages[0], messages
