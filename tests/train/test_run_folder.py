"""The run folder's one owner: config.json written with its format version, read back checked, older runs migrated."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from visualenv.train.run_folder import (
    FORMAT,
    FORMAT_VERSION,
    RunFolder,
    RunFolderError,
    legacy_eval_seed,
    migrate,
    read_config,
    read_run,
    record_run,
    write_config,
    write_results,
)
from visualenv.train.run_settings import SETTINGS, settings

RESULTS = Path(__file__).resolve().parents[2] / "results"
SB3_FIRST = {
    "spec": "Goalie-v0",
    "algo": "ppo",
    "steps": 1000,
    "envs": 2,
    "frame_stack": 4,
    "eval_every": 500,
    "eval_episodes": 10,
    "final_eval_episodes": 20,
    "seed": 3,
    "render": True,
    "hyperparams": {"n_steps": 64},
    "progress": False,
}  # an SB3 run's settings before pin, batched, workers and render_device
FIGURES = {
    "eval_seed": 2**33 + 3,
    "episodes": 2,
    "mean_reward": 1.5,
    "std_reward": 0.5,
    "mean_length": 10.0,
    "success_rate": 0.5,
    "per_episode": {"returns": [1.0, 2.0], "lengths": [10, 10], "successes": [True, False]},
}


def current(config=None, **record):
    added = {"pin": True, "batched": False, "workers": None, "render_device": None, "augment": None}
    return {
        "backend": "sb3",
        "command": "visualenv train Goalie-v0",
        "config": {**SB3_FIRST, **added, **(config or {})},
        "versions": {"visualenv": "0.1.0"},
        "spec_path": "specs/goalie.yaml",
        **record,
    }


def test_every_committed_run_reads_through_the_run_folder():
    """The shipped agents' folders (and the runs kept beside them) are older runs: each migrates and checks."""
    configs = sorted(RESULTS.rglob("config.json"))
    assert len(configs) >= 7
    backends = {}
    for path in configs:
        run = read_run(path.parent)
        assert run.record["format_version"] == FORMAT_VERSION
        assert set(run.config) == set(settings(run.record["backend"]))
        backends[path.parent.relative_to(RESULTS).as_posix()] = run.record["backend"]
        if run.results is not None:
            assert run.note is None and isinstance(run.results["eval_seed"], int)
    assert backends["Goalie-v0"] == "sb3" and backends["Goalie-v0-rllib"] == "rllib"
    assert backends["DMC-cartpole-swingup-v0"] == "distill"
    for env_id in ("Goalie-v0", "Goalie-v0-rllib", "LunarLanding-v0", "VisualCartPole-v0"):
        assert RunFolder(RESULTS / env_id).shipped_policy.is_file()
        on_disk = json.loads((RESULTS / env_id / "config.json").read_text())
        assert on_disk.get("format_version") is None  # read, not rewritten


def test_config_round_trips_with_its_format_version(tmp_path):
    record = current(resumes=[{"command": "visualenv train --resume x", "hyperparams": {"ent_coef": 0.01}}])
    path = write_config(tmp_path, record)
    on_disk = json.loads(path.read_text())
    assert on_disk["format"] == FORMAT and on_disk["format_version"] == FORMAT_VERSION
    assert path == RunFolder(tmp_path).config
    assert read_config(tmp_path) == {"format": FORMAT, "format_version": FORMAT_VERSION, **record}
    assert write_results(tmp_path, FIGURES) == RunFolder(tmp_path).results and read_run(tmp_path).results == FIGURES


def test_a_resumed_older_run_is_written_in_the_current_format(tmp_path):
    (tmp_path / "config.json").write_text(json.dumps({"command": "visualenv train Goalie-v0", "config": SB3_FIRST}))
    resumed = {**SB3_FIRST, "steps": 2000, "pin": True, "batched": False, "workers": None, "render_device": None}
    resumed["augment"] = None
    record_run(tmp_path, resumed, "specs/goalie.yaml", backend="sb3", resume=True, changes={"ent_coef": 0.02})
    record = json.loads((tmp_path / "config.json").read_text())
    assert record["format_version"] == FORMAT_VERSION and record["backend"] == "sb3"
    assert record["config"]["steps"] == 2000
    assert record["resumes"][-1]["hyperparams"] == {"ent_coef": 0.02}


def test_older_configs_are_migrated():
    sb3 = migrate({"command": "c", "config": SB3_FIRST}).record
    assert sb3["backend"] == "sb3" and sb3["format_version"] == FORMAT_VERSION
    assert {k: sb3["config"][k] for k in ("pin", "batched", "workers", "render_device")} == {
        "pin": True,
        "batched": False,
        "workers": None,
        "render_device": None,
    }
    rllib_config = {k: v for k, v in SB3_FIRST.items() if k not in ("algo", "envs")}
    rllib_config.update(env_runners=2, envs_per_runner=1, algo="ppo", backend="rllib")
    rllib = migrate({"command": "c", "backend": "rllib", "config": rllib_config}).record
    assert rllib["backend"] == "rllib" and rllib["config"]["pin"] is True and rllib["config"]["batched"] is False
    distill_config = {
        "spec": "Goalie-v0",
        "teacher": "t.safetensors",
        "rounds": 2,
        "episodes": 4,
        "mixing": 0,
        "epochs": 1.0,
        "batch_size": 64,
        "learning_rate": 3e-4,
        "shift": 4,
        "frame_stack": 3,
        "eval_episodes": 2,
        "final_eval_episodes": 2,
        "seed": 0,
        "progress": True,
        "algo": "dagger",
        "render": True,
    }
    distill = migrate({"command": "c", "config": distill_config, "teacher": {"path": "t", "sha256": "0"}}).record
    assert distill["backend"] == "distill" and distill["config"]["student"] is None
    assert migrate(sb3).record == sb3  # the current format stays as it is


def test_older_results_take_the_legacy_stream_and_its_resets(tmp_path):
    (tmp_path / "config.json").write_text(json.dumps({"command": "c", "config": SB3_FIRST}))
    older = {k: v for k, v in FIGURES.items() if k != "eval_seed"}
    (tmp_path / "results.json").write_text(json.dumps({**older, "reevaluated": {"file": "policy.pt"}}))
    np.savez(tmp_path / "evaluations.npz", timesteps=np.array([500, 1000]), results=np.zeros((2, 10)))
    run = read_run(tmp_path)  # no progress log: the resets of the periodic evaluations cannot be counted
    assert run.results["eval_seed"] == legacy_eval_seed(3) == 10_003 and "reevaluated" not in run.results
    assert "cannot be counted" in run.note
    (tmp_path / "logs").mkdir()
    rows = ["time/iterations,time/total_timesteps", "1,128", "2,256", "3,384"]  # the segment started at step 0
    (tmp_path / "logs" / "progress.csv").write_text("\n".join(rows) + "\n")
    run = read_run(tmp_path)
    assert run.note is None and run.results["resets_before"] == 1 + 2 * (10 + 1)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"eval_episodes": 10**9}, r"config.eval_episodes: expected an integer from 1 to 1000000, got 1000000000"),
        ({"eval_episodes": "10"}, r"config.eval_episodes: expected an integer, got str '10'"),
        ({"frame_stack": True}, r"config.frame_stack: expected an integer, got bool True"),
        ({"seed": -1}, r"config.seed: expected an integer from 0 to 2147483647, got -1"),
        ({"algo": "dagger"}, r"config.algo: a sb3 run trains ppo, a2c, dqn, sac, not 'dagger'"),
        ({"render_device": "tpu"}, r"config.render_device: expected one of cpu, gpu, got 'tpu'"),
        ({"workers": 3}, r"config.workers: 3 workers for 2 envs"),
        ({"learning_rate": 1e-4}, r"unknown setting config.learning_rate for a sb3 run"),
    ],
)
def test_settings_out_of_bounds_are_refused_with_what_was_expected(tmp_path, change, message):
    (tmp_path / "config.json").write_text(json.dumps(current(change)))
    with pytest.raises(RunFolderError, match=message):
        read_config(tmp_path)
    with pytest.raises(RunFolderError, match=message):
        write_config(tmp_path, current(change))


def test_a_distillations_distractions_are_a_list_or_a_section():
    """config.json records `--distractions` as [difficulty], [low, high], or the section given as a mapping."""
    rule = SETTINGS["distractions"]
    assert rule.problem([0.1, 0.3]) is None and rule.problem({"difficulty": 0.2, "camera": False}) is None
    assert rule.problem("hard") == "expected a list or a mapping, got str 'hard'"


def test_broken_or_foreign_run_folders_are_refused(tmp_path):
    with pytest.raises(RunFolderError, match="is not a run folder of `visualenv train`"):
        read_config(tmp_path)
    assert read_run(tmp_path).record is None and read_run(tmp_path).results is None
    no_steps = {"command": "c", "config": {k: v for k, v in SB3_FIRST.items() if k != "steps"}}
    later = {**current(), "format": FORMAT, "format_version": FORMAT_VERSION + 1}
    for text, message in [
        ("{", "not JSON"),
        ('{"config": {}}', "a sb3 run's config lacks spec"),
        ("[]", "no 'config' mapping"),
        (json.dumps(no_steps), "lacks steps"),
        (json.dumps(later), "written by a later visualenv"),
    ]:
        (tmp_path / "config.json").write_text(text)
        with pytest.raises(RunFolderError, match=message):
            read_config(tmp_path)
    write_config(tmp_path, current())
    for bad, message in [
        ({"success_rate": 1.5}, "success_rate: expected a number from 0 to 1"),
        ({"episodes": 3}, "per_episode.returns: expected a list of 3 episodes"),
        ({"mean_reward": float("nan")}, "mean_reward: expected a number"),
        ({"eval_seed": 2.5}, "eval_seed: expected an integer, got float"),
    ]:
        with pytest.raises(RunFolderError, match=message):
            write_results(tmp_path, {**FIGURES, **bad})
        (tmp_path / "results.json").write_text(json.dumps({**FIGURES, **bad}))
        with pytest.raises(RunFolderError, match=message):
            read_run(tmp_path)


def test_each_backend_records_exactly_the_settings_of_its_config_class():
    from visualenv.train.distill import DistillConfig
    from visualenv.train.rllib import RLlibTrainConfig
    from visualenv.train.sb3 import TrainConfig

    def names(cls):
        return {f.name for f in dataclasses.fields(cls)}

    assert set(settings("sb3")) == names(TrainConfig) and set(settings("rllib")) == names(RLlibTrainConfig)
    assert set(settings("distill")) == names(DistillConfig) | {"algo", "render"}  # distill records both for eval


def test_the_logs_of_a_run_and_of_a_shipped_agent(tmp_path):
    folder = RunFolder(tmp_path)
    folder.logs.mkdir()
    folder.progress.write_text("a\n")
    folder.keep_earlier_progress()
    folder.progress.write_text("b\n")
    folder.keep_earlier_progress()
    folder.progress.write_text("c\n")
    assert [p.read_text() for p in folder.progress_parts()] == ["a\n", "b\n", "c\n"]
    shipped = RunFolder(tmp_path / "shipped")  # results/<Id>/: the logs beside config.json
    shipped.path.mkdir()
    for name in ("progress-1.csv", "progress.csv"):
        (shipped.path / name).write_text(name)
    assert [p.name for p in shipped.progress_parts()] == ["progress-1.csv", "progress.csv"]


def test_a_bound_that_is_open_refuses_the_bound_itself():
    """``--zoom`` scales by 1 - zoom, so config.json refuses zoom 1 as the CLI does (its range is open at 1)."""
    rule = SETTINGS["zoom"]
    assert rule.problem(0.999) is None and rule.problem(0.0) is None
    assert rule.problem(1.0) == "expected a number from 0 below 1, got 1.0"
    assert SETTINGS["learning_rate"].problem(0) == "expected a number above 0 to 1, got 0"
