"""`bench --phases` splits a step into columns that add up to it, and renders its shader copies without leaving them."""

import json
import math

import pytest
from click.testing import CliRunner

from visualenv.cli import main
from visualenv.tools.bench import blender_data_blocks
from visualenv.tools.bench_phases import COLUMNS
from visualenv.tools.render_events import MARKED, SYNC_PARTS

pytestmark = pytest.mark.blender


def test_phases_prints_every_column_and_they_add_up_to_the_step(tmp_path):
    out = tmp_path / "phases.json"
    blocks = blender_data_blocks()
    result = CliRunner().invoke(
        main, ["bench", "specs/visual_cartpole.yaml", "--phases", "--steps", "12", "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    header = next(line for line in result.output.splitlines() if line.startswith("| spec | pixels | step |"))
    names = [cell.strip() for cell in header.strip("|").split("|")]
    assert names == ["spec", "pixels", "step", *COLUMNS, "floor", "skybox", "bodies"]
    row = next(line for line in result.output.splitlines() if line.startswith("| VisualCartPole-v0 | 100x100"))
    cells = dict(zip(names, (cell.strip() for cell in row.strip("|").split("|"))))
    assert all(float(cells[column]) >= 0 for column in ("step", *COLUMNS))
    # the scene has bodies, no floor, and a world of one colour already
    assert cells["floor"] == cells["skybox"] == "-" and cells["bodies"][0] in "+-"
    for figure in (*COLUMNS, "floor/skybox/bodies"):
        assert f"  {figure}: " in result.output  # how each is obtained
    record = json.loads(out.read_text())[0]
    columns = record["columns_ms"]
    assert set(columns) == set(COLUMNS) and min(columns.values()) >= 0 and record["step_ms"] > 0
    assert math.isclose(sum(columns.values()), record["step_ms"], rel_tol=1e-6)
    assert math.isclose(sum(record["sync_ms"][part] for part in SYNC_PARTS), columns["sync"], rel_tol=1e-6)
    assert columns["trace"] > 0 and record["steps"] == 6  # every other step recorded
    assert set(record["ablation"]["parts"]) == {"bodies"} and record["ablation"]["control_call_ms"] > 0
    # every step's call is also cut at Cycles' marks alone, with and without the lines
    assert "the render call cut at Cycles' marks alone" in result.output
    for marked in record["marked_ms"].values():
        assert set(marked) == set(MARKED) and min(marked.values()) >= 0 and marked["cycles_render"] > 0
    assert blender_data_blocks() == blocks  # the env and the copies are gone


def test_phases_refuse_a_batch():
    result = CliRunner().invoke(main, ["bench", "specs/visual_cartpole.yaml", "--phases", "--batched", "4"])
    assert result.exit_code != 0 and "--phases" in result.output and "Traceback" not in result.output
