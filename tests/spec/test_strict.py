"""The spec is read strictly: what YAML or pydantic would quietly coerce is refused with a located reason.

The bad-spec corpus holds one file per case; these tests sweep the families
(every quoted number, every YAML 1.1 boolean word as a key, every base-60
number) and the cases a corpus file cannot hold (a 100k-value document).
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from visualenv.errors import SpecError
from visualenv.spec import source
from visualenv.spec.loader import load_spec, load_spec_text

BASE = """\
id: T-v0
state:
  x: {init: 0}
actions:
  discrete: [{u: 1}]
"""


def _problems(text: str, name: str = "spec.yaml") -> list[str]:
    try:
        load_spec_text(text, name)
    except SpecError as exc:
        return [str(d) for d in exc.diagnostics]
    return []


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 10**8), st.sampled_from(['"{}"', "'{}'", '"{}.0"']))
def test_a_quoted_number_is_refused_and_the_bare_number_accepted(n: int, quoting: str):
    assert _problems(BASE + f"max_steps: {n}\n") == []
    problems = _problems(BASE + f"max_steps: {quoting.format(n)}\n")
    assert len(problems) == 1 and "spec.yaml:6:12: max_steps: expected an integer" in problems[0]
    assert "without quotes" in problems[0]


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 99), st.integers(0, 59))
def test_a_base60_number_is_not_read_as_a_number(hours: int, minutes: int):
    problems = _problems(BASE + f"max_steps: {hours}:{minutes:02d}\n")
    assert len(problems) == 1 and "base-60" in problems[0], problems


@pytest.mark.parametrize("field, value", [("max_steps", "true"), ("dt", "false"), ("render: {samples", "true}")])
def test_a_boolean_is_not_a_number(field: str, value: str):
    problems = _problems(BASE + f"{field}: {value}\n")
    assert len(problems) == 1 and "a boolean is not a number" in problems[0], problems


@pytest.mark.parametrize("word", ["on", "off", "yes", "no", "true", "false", "On", "YES", "null", "~"])
def test_a_yaml_boolean_or_null_key_says_to_quote_it(word: str):
    problems = _problems(f"id: T-v0\nstate:\n  {word}: {{init: 0}}\nactions:\n  discrete: [{{u: 1}}]\n")
    assert len(problems) == 1 and problems[0].startswith("spec.yaml:3:3: state: YAML 1.1 reads the key"), problems
    assert f"quote it ('{word}':)" in problems[0]


def test_a_flat_sum_of_45_terms_is_accepted():
    assert _problems(BASE + "reward: " + " + ".join(["x"] * 45) + "\n") == []


def test_a_toml_file_with_a_byte_order_mark_loads(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b'\xef\xbb\xbfid = "T-v0"\n[state.x]\ninit = 0\n[actions]\ndiscrete = [{u = 1}]\n')
    assert load_spec(path).spec.id == "T-v0"


def test_a_large_document_without_aliases_is_not_blamed_on_aliases(monkeypatch):
    monkeypatch.setattr(source, "MAX_VALUES", 500)
    params = "".join(f"  p{i}: {i}\n" for i in range(600))
    problems = _problems("id: T-v0\nparams:\n" + params + BASE[len("id: T-v0\n") :])
    assert len(problems) == 1 and "too large: more than 500 values" in problems[0]
    assert "alias" not in problems[0]
    bomb = (
        "a: &a [1, 1, 1, 1, 1, 1, 1, 1]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a]\nc: [*b, *b, *b, *b, *b, *b, *b, *b]\n"
    )
    assert "YAML aliases expand" in _problems(bomb)[0]
