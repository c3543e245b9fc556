"""JSON from elsewhere (policy.json, a run folder's config.json and results.json) nested 200,000 deep: a located error
at once, where json.loads would end in a RecursionError."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from visualenv.cli import main
from visualenv.train.run_folder import RunFolderError, read_config, read_run

ROOT = Path(__file__).parents[2]
DEEP = "[" * 200_000 + "]" * 200_000


def test_a_deep_policy_json_is_a_one_line_error_in_eval(tmp_path: Path) -> None:
    (tmp_path / "policy.json").write_text(DEEP)
    (tmp_path / "policy.safetensors").write_bytes(b"")
    start = time.monotonic()
    result = CliRunner().invoke(
        main, ["eval", str(ROOT / "specs" / "visual_cartpole.yaml"), "--model", str(tmp_path / "policy.safetensors")]
    )
    assert time.monotonic() - start < 20
    assert result.exit_code != 0 and "Traceback" not in result.output and "RecursionError" not in result.output
    assert "policy.json: not JSON (lists and objects nested 200000 deep, more than the 64 levels" in result.output


@pytest.mark.parametrize("name", ["config.json", "results.json"])
def test_a_deep_run_folder_file_is_a_located_error(tmp_path: Path, name: str) -> None:
    (tmp_path / name).write_text(DEEP)
    with pytest.raises(RunFolderError, match=f"{name}: not JSON \\(lists and objects nested 200000 deep"):
        read_config(tmp_path) if name == "config.json" else read_run(tmp_path)
