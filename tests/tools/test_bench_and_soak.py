"""The benchmark prints every figure; a short soak keeps Blender data and memory flat.

Expected core shares come from this process's usable cores (``worker_cores``), so the
tests hold on 1, 2, 4, 8 or 16 cores (docs/testing.md: run them under ``taskset``).
"""

import json

import pytest

from click.testing import CliRunner

import visualenv
from visualenv.cli import main
from visualenv.env.cores import worker_cores
from visualenv.tools.bench import StepTimes, soak

pytestmark = pytest.mark.blender


def expected_share(workers: int) -> tuple[bool, object]:
    """(pinned, cores_each) that `bench --workers N` reports on this machine: each worker's own cores where there are
    two or more to share, else none confined ('all')."""
    shares = worker_cores(workers)
    return shares[0] is not None, len(shares[0]) if shares[0] else "all"


def test_bench_prints_every_figure(tmp_path):
    out = tmp_path / "bench.json"
    result = CliRunner().invoke(
        main, ["bench", "VisualCartPole-v0", "--steps", "30", "--workers", "2", "--soak", "50", "--json", str(out)]
    )
    assert result.exit_code == 0, result.output
    for label in [
        "env steps/s",
        "render call (median/p99)",
        "raw render floor",
        "with objects moved",
        "naive PNG round trip",
        "framework overhead",
        "outside the render call",
        "speed vs floor / naive",
        "resident memory",
        "2 parallel envs",
        "step in a worker",
        "per worker",
        "soak: 50 steps",
    ]:
        assert label in result.output, label
    assert (
        result.output.count("render call (median/p99)") == 2 and result.output.count("outside the render call") == 2
    )  # one env, then the workers
    figures = json.loads(out.read_text())[0]
    assert (
        figures["steps_per_s"] > 0
        and figures["floor_ms_median"] > 0
        and figures["moved_floor_ms_median"] > 0
        and 0 <= figures["own_overhead_share"] < 1
    )
    assert 0 < figures["outside_ms_median"] < figures["step_ms_median"]
    parallel = figures["parallel"]
    pinned, cores_each = expected_share(2)
    assert (
        parallel["workers"] == 2
        and parallel["pinned"] is pinned
        and parallel["cores_each"] == cores_each
        and parallel["steps_per_s"] > 0
    )
    assert 0 < parallel["render_ms_median"] and 0 < parallel["outside_share"] < 1
    # each worker holds a Blender of its own (one bpy process alone is about 300 MB), and the total is theirs
    each = parallel["rss_each_mb"]
    assert (
        len(each) == 2
        and min(each) > 100
        and parallel["rss_total_mb"] == sum(each)
        and parallel["rss_final_mb"] == max(each)
    )


def test_bench_measures_scaling_against_one_confined_worker(tmp_path):
    out = tmp_path / "bench.json"
    result = CliRunner().invoke(
        main, ["bench", "VisualCartPole-v0", "--steps", "30", "--workers", "1,2", "--json", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "scaling: one worker confined to one core" in result.output and "vs n x one confined" in result.output
    one, *rows = json.loads(out.read_text())[0]["scaling"]
    assert (
        one["workers"] == 1
        and one["cores_each"] == 1
        and one["threads"] == 1
        and one["pinned"] is True
        and one["steps_per_s"] > 0
    )
    assert [r["workers"] for r in rows] == [1, 2] and all(r["vs_confined"] > 0 for r in rows)
    pinned, cores_each = expected_share(
        2
    )  # two workers: half the cores each (one on two cores), none confined on one core
    assert rows[1]["cores_each"] == cores_each and rows[1]["pinned"] is pinned
    assert (
        rows[0]["pinned"] is False and rows[0]["cores_each"] == "all"
    )  # one worker of the scaling rows is never confined


def test_bench_compares_batches_with_the_per_process_vector_env(tmp_path):
    out = tmp_path / "bench.json"
    result = CliRunner().invoke(
        main,
        [
            "bench",
            "VisualCartPole-v0",
            "--steps",
            "20",
            "--batched",
            "1,3",
            "--autoreset",
            "same_step",
            "--device",
            "cpu",
            "--json",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    assert (
        "batched (one process, autoreset same_step)" in result.output
        and "per-process vector env, 2 workers" in result.output
    )
    (record,) = json.loads(out.read_text())
    assert [b["envs"] for b in record["batched"]] == [1, 3]
    assert all(b["autoreset"] == "same_step" and b["calls_per_step"] >= 1 for b in record["batched"]), record
    assert all(
        b["steps_per_s"] > 0 and b["render_ms"] > 0 and b["rss_mb"] > 0 and b["alone_ms"] > 0 for b in record["batched"]
    ), record
    assert record["per_process"]["workers"] == 2 and record["per_process"]["steps_per_s"] > 0
    bad = CliRunner().invoke(main, ["bench", "VisualCartPole-v0", "--batched", "0,4"])
    assert bad.exit_code == 2 and "expected batch sizes or a list such as 1,2,4,8, got '0,4'" in bad.output


def test_bad_arguments_are_refused_before_anything_runs(tmp_path):
    (tmp_path / "afile").write_text("")
    result = CliRunner().invoke(
        main, ["bench", "VisualCartPole-v0", "--json", str(tmp_path / "afile" / "figures.json")]
    )
    assert result.exit_code == 2 and "cannot write" in result.output and "env steps/s" not in result.output
    for args in (["build", "Goalie-v0", "--out"], ["preview", "Goalie-v0", "--out"], ["train", "Goalie-v0", "--out"]):
        result = CliRunner().invoke(main, [*args, str(tmp_path / "afile" / "out")])
        assert (
            result.exit_code == 1 and "cannot create the folder" in result.output and "Not a directory" in result.output
        ), args
    result = CliRunner().invoke(main, ["play", "Goalie-v0", "--record", str(tmp_path / "afile" / "play.gif")])
    assert result.exit_code == 2 and "cannot create the folder" in result.output
    for workers in ("-1", "1,x", "0,2"):
        result = CliRunner().invoke(main, ["bench", "VisualCartPole-v0", "--workers", workers])
        assert result.exit_code == 2 and "expected a number of workers or a list such as 1,2,4,8" in result.output, (
            workers
        )
    for args in (
        ["bench", "VisualCartPole-v0", "--steps", "0"],
        ["play", "Goalie-v0", "--episodes", "0"],
        ["train", "Goalie-v0", "--envs", "0"],
        ["preview", "Goalie-v0", "--steps", "0"],
        ["build", "Goalie-v0", "--seed", "-1"],
        ["play", "Goalie-v0", "--seed", "-1"],
    ):
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 2 and "is not in the range" in result.output, args


def test_the_moved_floor_writes_each_steps_state_mujocos_bodies_included():
    """bench's moved floor renders each step's state again: a kept copy of an earlier state (MuJoCo's poses are live
    views of the simulation) draws that step's observation, and writing it alone puts the cart where it was then."""
    import numpy as np

    env = visualenv.make("DMC-cartpole-swingup-v0")
    try:
        obs, _ = env.reset(seed=0)
        base = env.unwrapped
        kept, first = base.frames().copy(), obs
        objects = list(base.renderer.scene.objects)

        def places() -> list[tuple[float, ...]]:
            return [(*o.location, *o.rotation_quaternion) for o in objects]  # what the poses write

        where = places()
        for _ in range(12):
            later = env.step(np.ones(1, np.float32))[0]
        assert np.abs(later.astype(int) - first.astype(int)).max() > 30  # the cart moved on
        moved = [k for k, (a, b) in enumerate(zip(where, places())) if a != b]
        assert moved  # MuJoCo's bodies, placed by the poses (no binding moves them)
        base.renderer.write(kept)
        assert [places()[k] for k in moved] == [where[k] for k in moved]
        again = base.renderer.render(kept)[0]
        assert np.array_equal(again, first)  # the earlier state's frame, bit for bit
    finally:
        env.close()


def test_step_times_pairs_each_step_with_its_render_calls():
    env = StepTimes(visualenv.make("VisualCartPole-v0"))
    try:
        env.reset(seed=0)
        renderer = env.unwrapped.renderer
        env.start_timing()
        for _ in range(5):
            env.step(0)
        timings = env.timings()
        assert (
            len(timings["step"]) == len(timings["render"]) == len(timings["outside"]) == 5
        )  # one observation render per step
        # each step's own render call was timed inside it: a step outlasts its render (actions, dynamics, readback)
        assert all(0 < render < step for step, render in zip(timings["step"], timings["render"]))
        assert renderer.profile is None  # timing stopped: the renderer records nothing more
        env.step(0)
        assert len(timings["step"]) == 5
        env.start_timing()
        env.start_timing()  # again while timing: still one timed render per step, in the new lists
        env.step(0)
        again = env.timings()
        assert len(again["step"]) == len(again["render"]) == 1 and 0 < again["outside"][0] < again["step"][0]
    finally:
        env.close()


@pytest.mark.slow
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
    from visualenv.tools.bench import blender_data_blocks

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


def test_a_measuring_process_that_dies_is_reported_not_waited_for():
    """A batch size whose process dies (a crashed Blender or GPU driver) gives an error row, and the next size goes on."""
    import multiprocessing
    import os

    from visualenv.tools.bench_batch import _result_of

    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    child = context.Process(target=os._exit, args=(3,))
    child.start()
    assert _result_of(child, queue, 64) == {"envs": 64, "error": "the measuring process died (exit code 3)"}


def test_blenders_render_call_alone_then_read_again_gives_that_states_observation():
    """step_gap.py's public hooks: a written state, Blender's render call alone (raw_render) and the readback alone
    (read_again) give the frame a step gave for that state; with the file readback there is nothing to read again."""
    import numpy as np

    from visualenv.errors import RenderError

    env = visualenv.make("VisualCartPole-v0")
    try:
        first, _ = env.reset(seed=0)
        base = env.unwrapped
        kept = base.frames().copy()
        for _ in range(8):
            later = env.step(1)[0]
        assert np.abs(later.astype(int) - first.astype(int)).max() > 30  # the cart moved
        base.renderer.write(kept)
        base.renderer.raw_render()
        assert np.array_equal(base.renderer.read_again(), first)
    finally:
        env.close()
    env = visualenv.make("VisualCartPole-v0", readback="file")
    try:
        env.reset(seed=0)
        with pytest.raises(RenderError, match="no in-memory render to read again"):
            env.unwrapped.renderer.read_again()
    finally:
        env.close()
