"""A spec file's size is checked before it is read: a spec of megabytes took minutes to parse and check."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from visualenv.cli import main
from visualenv.errors import SpecError
from visualenv.spec import load_spec_text
from visualenv.spec.source import MAX_SPEC_BYTES


def test_a_5_mb_spec_is_refused_at_once(tmp_path: Path) -> None:
    lines = ["id: Big-v0", "state: {x: {init: 0}}", "actions: {discrete: [{}]}", "params:"]
    lines += [f"  p{i}: {i}" for i in range(350_000)]
    spec = tmp_path / "big.yaml"
    spec.write_text("\n".join(lines) + "\n")
    assert spec.stat().st_size > 5_000_000
    start = time.monotonic()
    result = CliRunner().invoke(main, ["validate", str(spec)])
    assert time.monotonic() - start < 10
    assert result.exit_code != 0 and "Traceback" not in result.output
    assert f"big.yaml: the spec is {spec.stat().st_size} bytes, more than the {MAX_SPEC_BYTES}" in result.output


def test_spec_text_given_in_python_has_the_same_limit() -> None:
    with pytest.raises(SpecError, match="more than the 1048576 a spec may have"):
        load_spec_text("id: Big-v0\ndescription: '" + "x" * MAX_SPEC_BYTES + "'\n", name="big.yaml")
