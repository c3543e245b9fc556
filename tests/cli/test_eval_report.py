"""`visualenv eval` reports a success rate only for a spec that says what a success is."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from visualenv.cli import main

pytestmark = pytest.mark.blender  # eval records the machine it ran on, Blender's build among it


@pytest.mark.parametrize(("env_id", "rated"), [("Goalie-v0", True), ("DMC-cartpole-swingup-v0", False)])
def test_a_success_rate_is_reported_only_where_the_spec_declares_success(env_id: str, rated: bool) -> None:
    pytest.importorskip("mujoco")
    result = CliRunner().invoke(main, ["eval", env_id, "--model", "random", "--episodes", "2"])
    assert result.exit_code == 0, result.output
    assert "mean return" in result.output
    assert ("success rate" in result.output) == rated, result.output
