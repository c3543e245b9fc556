"""--trust-code: the CLI imports a spec's ``dynamics.python`` only when told to; `validate` never does
(docs/security.md). The probe spec is state-only: only eval's record of the machine reads Blender."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from visualenv.cli import main
from tests.fixtures.hostile_code import hostile_spec


@pytest.fixture
def probe(tmp_path, monkeypatch):
    return hostile_spec(tmp_path, monkeypatch)


def refused(probe, args: list[str]) -> None:
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    assert f"{probe.path}:5:" in result.output and f"imports the module '{probe.module}'" in result.output
    assert "pass --trust-code" in result.output and "Traceback" not in result.output
    assert not probe.imported


def test_validate_checks_the_reference_and_imports_nothing(probe):
    result = CliRunner().invoke(main, ["validate", str(probe.path)])
    assert result.exit_code == 0, result.output
    assert result.output.startswith("ok (dynamics.python ") and "not imported" in result.output
    assert "--trust-code" in result.output
    assert not probe.imported


def test_validate_locates_a_malformed_reference(probe):
    probe.path.write_text(probe.path.read_text().replace(f"{probe.module}:step", "os.import:step"))
    result = CliRunner().invoke(main, ["validate", str(probe.path)])
    assert result.exit_code == 2 and f"{probe.path}:5:" in result.output
    assert "'import' in 'os.import:step' is a Python keyword" in result.output


def test_commands_that_make_the_env_refuse_without_the_flag_before_writing(probe, tmp_path):
    spec = str(probe.path)
    refused(probe, ["build", spec, "-o", str(tmp_path / "build")])
    assert not (tmp_path / "build").exists()
    refused(probe, ["preview", spec, "-o", str(tmp_path / "frames")])
    refused(probe, ["eval", spec, "--model", "random", "--episodes", "1"])
    refused(probe, ["bench", spec, "--steps", "1", "--workers", "0"])
    refused(probe, ["train", spec, "--state-only", "--steps", "8", "-o", str(tmp_path / "runs")])
    assert not (tmp_path / "runs").exists()


@pytest.mark.blender  # eval records the machine, Blender's version included
def test_eval_runs_the_spec_with_the_flag(probe, tmp_path):
    out = tmp_path / "eval.json"
    args = ["eval", str(probe.path), "--model", "random", "--episodes", "2", "--trust-code", "-o", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert probe.imported and json.loads(out.read_text())["episodes"] == 2
