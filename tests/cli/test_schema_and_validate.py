"""The JSON Schema is in sync with the models; the CLI's validate/schema commands."""

import json
from pathlib import Path

from click.testing import CliRunner

from visualenv.cli import main
from visualenv.spec.schema import spec_json_schema

ROOT = Path(__file__).resolve().parents[2]


def test_committed_schema_matches_the_models():
    committed = json.loads((ROOT / "schemas" / "visualenv.schema.json").read_text())
    assert committed == spec_json_schema(), "run `make schema` and commit schemas/visualenv.schema.json"


def test_validate_ok_prints_one_line():
    result = CliRunner().invoke(main, ["validate", str(ROOT / "specs" / "visual_cartpole.yaml")])
    assert result.exit_code == 0 and result.output == "ok\n"


def test_validate_reports_unknown_name_with_position_and_names(tmp_path):
    text = (
        (ROOT / "specs" / "visual_cartpole.yaml")
        .read_text()
        .replace("theta: theta + tau * theta_dot", "theta: thta + tau * theta_dot")
    )
    broken = tmp_path / "broken.yaml"
    broken.write_text(text)
    line = next(i for i, row in enumerate(text.splitlines(), 1) if "thta +" in row)
    column = text.splitlines()[line - 1].index("thta") + 1
    result = CliRunner().invoke(main, ["validate", str(broken)])
    assert result.exit_code == 2
    assert (
        f"{broken}:{line}:{column}: dynamics.update.theta: unknown name 'thta' (did you mean 'theta'? names: x, x_dot, theta, theta_dot,"
        in result.output
    )
    assert "Traceback" not in result.output


def test_schema_command_prints_the_schema():
    result = CliRunner().invoke(main, ["schema"])
    assert result.exit_code == 0 and json.loads(result.output)["title"] == "visualenv spec"


def test_every_command_that_writes_a_folder_takes_o_for_out():
    writers = {name: cmd for name, cmd in main.commands.items() if any("--out" in p.opts for p in cmd.params)}
    assert {"build", "preview", "train"} <= set(writers)
    for name, cmd in writers.items():
        out = next(p for p in cmd.params if "--out" in p.opts)
        assert "-o" in out.opts, f"visualenv {name}: -o is not the short form of --out"


def test_o_without_a_folder_is_a_one_line_error():
    result = CliRunner().invoke(main, ["build", str(ROOT / "specs" / "visual_cartpole.yaml"), "-o"])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "Option '-o' requires an argument" in result.output
