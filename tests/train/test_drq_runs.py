"""`visualenv train --augment shift` end to end with real rendering (tiny budgets): PPO and DrQ's SAC."""

import json

import pytest
from click.testing import CliRunner

from visualenv.cli import main

pytestmark = [pytest.mark.blender, pytest.mark.slow]

TINY = ["--envs", "1", "--eval-every", "64", "--eval-episodes", "1", "--final-episodes", "2", "--no-progress"]


def _run(tmp_path, spec, *args):
    """The run folder of `train SPEC ARGS` on a tiny budget, and what it printed."""
    out = tmp_path / "runs"
    result = CliRunner().invoke(main, ["train", spec, *args, *TINY, "--out", str(out)])
    assert result.exit_code == 0, result.output
    (run,) = out.glob("*/*")
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


SIDE = """\
id: Side-v0
description: Push toward the side a dark cube stands on, seen in pixels (a contextual bandit of 4 steps).
scene:
  world: {color: [0.4, 0.4, 0.4], strength: 1.0}
  objects:
    Cube: {primitive: cube, size: 2.0, location: [0, 0, 0], material: {color: [0.02, 0.02, 0.02]}}
    Camera: {camera: perspective, lens: 24, location: [0, -6, 0], rotation: [1.5708, 0, 0]}
params:
  offset: 2.0
state:
  side: {init: "choice(-1.0, 1.0)"}
actions:
  continuous:
    push: {low: -1.0, high: 1.0}
dynamics:
  update:
    side: side
actors:
  Cube: {location: [offset * side, 0, 0]}
observation: {camera: Camera, resolution: [36, 36], color: grayscale}
render: {engine: workbench}
reward: push * side
max_steps: 4
"""


def test_drq_sac_learns_a_small_pixel_task(tmp_path):
    """Only the frame tells the side (left or right, drawn per episode) to push to: an agent blind to it scores about
    0 an episode, one that sees it up to 4. Every episode is cut by its time limit, so the buffer's kept final frames
    are used. DrQ's SAC learns it in 600 steps (2.25-2.65 on seeds 0-3; at 400 steps one seed in four had not yet,
    and which one moves with float rounding, so with the CPU: the margin is kept wide)."""
    spec = tmp_path / "side.yaml"
    spec.write_text(SIDE)
    run, output = _run(
        tmp_path,
        str(spec),
        "--algo",
        "sac",
        "--augment",
        "shift",
        "--frame-stack",
        "1",
        "--steps",
        "600",
        "--set",
        "learning_starts=50",
        "--set",
        "batch_size=32",
        "--set",
        "buffer_size=1000",
        "--set",
        "learning_rate=1e-3",
    )
    results = json.loads((run / "results.json").read_text())
    assert results["mean_reward"] > 1.5, output
    assert all(r > 0 for r in results["per_episode"]["returns"]), output  # the side is read on every episode
