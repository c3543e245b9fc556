"""Smoke runs of `visualenv train` and `visualenv play` with real rendering (tiny budgets)."""

import json

import imageio.v3 as iio
import numpy as np
import pytest
from click.testing import CliRunner

from visualenv.cli import main

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    result = CliRunner().invoke(main, [
        "train", "Goalie-v0", "--steps", "256", "--envs", "2", "--eval-every", "128", "--eval-episodes", "2",
        "--final-episodes", "2", "--set", "n_steps=64", "--set", "batch_size=64", "--out", str(out), "--no-progress",
    ])
    assert result.exit_code == 0, result.output
    runs = list((out / "Goalie-v0").iterdir())
    assert len(runs) == 1
    return runs[0]


def test_train_writes_a_complete_run_folder(run_dir):
    for name in ["config.json", "results.json", "best_model.zip", "final_model.zip", "checkpoints/latest.zip",
                 "evaluations.npz", "logs/progress.csv", "plots/rewards.png", "plots/lengths.png", "plots/fps.png"]:
        assert (run_dir / name).is_file(), name
    results = json.loads((run_dir / "results.json").read_text())
    assert results["episodes"] == 2 and results["steps"] >= 256
    assert -10 <= results["mean_reward"] <= 10 and 0 <= results["success_rate"] <= 1
    assert 15 <= results["mean_length"] <= 60  # Goalie episodes end when the ball crosses (~21 steps)
    config = json.loads((run_dir / "config.json").read_text())
    assert config["config"]["hyperparams"] == {"n_steps": 64, "batch_size": 64}
    assert list(iio.imread(run_dir / "plots" / "rewards.png").shape[2:]) in ([3], [4])


def test_train_resumes_from_the_latest_checkpoint(run_dir):
    result = CliRunner().invoke(main, ["train", "Goalie-v0", "--resume", str(run_dir), "--steps", "384", "--no-progress"])
    assert result.exit_code == 0, result.output
    assert json.loads((run_dir / "results.json").read_text())["steps"] >= 384


def test_play_with_the_trained_model_records_a_gif(run_dir, tmp_path):
    gif = tmp_path / "play.gif"
    result = CliRunner().invoke(main, ["play", "Goalie-v0", "--model", str(run_dir / "best_model.zip"), "--episodes", "1", "--record", str(gif)])
    assert result.exit_code == 0, result.output
    assert "episode 0: return" in result.output and "success" in result.output
    frames = iio.imread(gif)
    assert frames.ndim == 4 and frames.shape[0] >= 10  # one frame per step
    # the view beside the observation: the frames change as the ball rolls
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 0.5


def test_play_random_policy():
    result = CliRunner().invoke(main, ["play", "Goalie-v0", "--episodes", "2"])
    assert result.exit_code == 0, result.output
    assert result.output.count("episode ") == 2 and "mean return" in result.output
