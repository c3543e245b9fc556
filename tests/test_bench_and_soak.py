"""The benchmark prints every figure; a short soak keeps Blender data and memory flat."""

import json

from click.testing import CliRunner

import visualenv
from visualenv.bench import soak
from visualenv.cli import main


def test_bench_prints_every_figure(tmp_path):
    out = tmp_path / "bench.json"
    result = CliRunner().invoke(main, ["bench", "VisualCartPole-v0", "--steps", "30", "--workers", "2", "--soak", "50", "--json", str(out)])
    assert result.exit_code == 0, result.output
    for label in ["env steps/s", "render call (median/p99)", "raw render floor", "with objects moved", "naive PNG round trip", "framework overhead",
                  "speed vs floor / naive", "resident memory", "2 parallel envs", "soak: 50 steps"]:
        assert label in result.output, label
    figures = json.loads(out.read_text())[0]
    assert figures["steps_per_s"] > 0 and figures["floor_ms_median"] > 0 and figures["moved_floor_ms_median"] > 0 and 0 <= figures["own_overhead_share"] < 1 and figures["parallel"]["workers"] == 2


def test_short_soak_keeps_blender_data_blocks_and_memory_flat():
    env = visualenv.make("Goalie-v0")  # ~21-step episodes: many resets
    try:
        env.reset(seed=0)
        for _ in range(50):  # warm up allocations and Blender's persistent data
            env.step(env.action_space.sample())
        figures = soak(env, 400, seed=1)
    finally:
        env.close()
    assert figures["resets"] >= 10
    assert figures["blocks_end"] == figures["blocks_start"]
    assert figures["growth_mb"] < 50


def test_repeated_make_and_close_do_not_leak_blender_data():
    from visualenv.bench import blender_data_blocks

    env = visualenv.make("VisualCartPole-v0")
    env.reset(seed=0)
    env.close()
    before = blender_data_blocks()
    for i in range(5):
        env = visualenv.make("VisualCartPole-v0")
        env.reset(seed=i)
        env.step(0)
        env.close()
    assert blender_data_blocks() == before
