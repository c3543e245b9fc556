"""`visualenv train --augment shift` end to end with real rendering (tiny budgets): PPO and DrQ's SAC."""

import json

import pytest
from click.testing import CliRunner

from visualenv.cli import main

pytestmark = [pytest.mark.blender, pytest.mark.slow]

TINY = ["--envs", "1", "--eval-every", "64", "--eval-episodes", "1", "--final-episodes", "2", "--no-progress"]


def _run(tmp_path, env_id, *args):
    result = CliRunner().invoke(main, ["train", env_id, *args, *TINY, "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    (run,) = (tmp_path / env_id).iterdir()
    return run, result.output


def test_ppo_trains_with_shifted_frames(tmp_path):
    run, _ = _run(
        tmp_path, "Goalie-v0", "--augment", "shift", "--steps", "128", "--set", "n_steps=64", "--set", "batch_size=32"
    )
    assert json.loads((run / "config.json").read_text())["config"]["augment"] == "shift"
    assert json.loads((run / "results.json").read_text())["episodes"] == 2


def test_drq_sac_trains_states_its_buffer_and_its_policy_file_evaluates(tmp_path):
    run, output = _run(
        tmp_path,
        "LunarLanding-v0",
        "--algo",
        "sac",
        "--augment",
        "shift",
        "--frame-stack",
        "3",
        "--steps",
        "96",
        "--set",
        "buffer_size=500",
        "--set",
        "learning_starts=32",
        "--set",
        "batch_size=16",
    )
    assert "replay buffer: 500 transitions of 3x100x100 uint8 observations, each stored once" in output
    config = json.loads((run / "config.json").read_text())["config"]
    assert config["augment"] == "shift" and config["algo"] == "sac"
    meta = json.loads((run / "best_model.json").read_text())
    assert meta["policy"] == "visualenv.train.drq.DrQSACPolicy"
    evaluated = CliRunner().invoke(
        main, ["eval", "LunarLanding-v0", "--model", str(run / "best_model.safetensors"), "--episodes", "2"]
    )
    assert evaluated.exit_code == 0 and "reproduces" in evaluated.output, evaluated.output
