"""`eval`, `play`, `view`, `export-policy` and `distill` refuse hostile policy files, and what lies beside them, with
one located line and no traceback; `export-policy` replaces an existing pair only with --force; every refusal names
options its command has. The hostile files are made here from a small real policy (tests/fixtures/policy_files.py)."""

import json
import math
import time

import numpy as np
import pytest
from click.testing import CliRunner

from tests.fixtures.policy_files import (
    SPEC,
    as_int32,
    copy_of,
    huge_network,
    rewrite_meta,
    rewrite_weights,
    small_policy,
    with_value,
)
from visualenv.cli import main

pytest.importorskip("torch")


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    return small_policy(tmp_path_factory.mktemp("small"))


def _refused(args: list[str], message: str) -> str:
    started = time.perf_counter()
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.output
    assert result.output.startswith("error: ") and message in result.output, result.output
    assert "Traceback" not in result.output and isinstance(result.exception, SystemExit)
    assert time.perf_counter() - started < 30
    return result.output


HOSTILE = {
    "huge net_arch": (
        lambda w: rewrite_meta(w, huge_network),
        "does not hold the network policy.json describes (450,225,003 parameters; the file holds 251)",
    ),
    "NaN": (
        lambda w: rewrite_weights(w, with_value("action_net.weight", math.nan)),
        "policy.safetensors: tensor 'action_net.weight' holds 1 NaN or infinite values",
    ),
    "int32": (lambda w: rewrite_weights(w, as_int32), "is I32: a policy's weights are floating point"),
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_each_command_that_loads_a_policy_refuses_a_hostile_one(policy, tmp_path, case):
    make, message = HOSTILE[case]
    weights = str(make(copy_of(policy, tmp_path / "agent")))
    out = tmp_path / "out.safetensors"
    _refused(["eval", SPEC, "--model", weights, "--episodes", "1"], message)
    _refused(["export-policy", weights, str(out)], message)
    assert not out.exists() and not out.with_suffix(".json").exists()
    _refused(["play", SPEC, "--model", weights, "--episodes", "1"], message)
    _refused(["view", SPEC, "--model", weights, "--port", "0"], message)
    _refused(["distill", SPEC, "--teacher", weights, "-o", str(tmp_path / "runs")], message)
    assert not (tmp_path / "runs").exists()


def test_export_policy_replaces_an_existing_pair_only_with_force(policy, tmp_path):
    out = tmp_path / "exported.safetensors"
    first = CliRunner().invoke(main, ["export-policy", str(policy), str(out)])
    assert first.exit_code == 0, first.output
    before = out.read_bytes(), out.with_suffix(".json").read_bytes()
    _refused(["export-policy", "--float32", str(policy), str(out)], "already exist: pass --force")
    assert (out.read_bytes(), out.with_suffix(".json").read_bytes()) == before  # nothing replaced
    forced = CliRunner().invoke(main, ["export-policy", "--float32", "--force", str(policy), str(out)])
    assert forced.exit_code == 0 and "float32 weights" in forced.output, forced.output
    assert json.loads(out.with_suffix(".json").read_text())["dtype"] == "float32"


def test_distill_refuses_a_pickle_naming_only_what_it_takes(tmp_path):
    teacher = tmp_path / "teacher.zip"
    teacher.write_bytes(b"PK\x05\x06" + bytes(18))  # an empty zip: never opened
    output = _refused(
        ["distill", SPEC, "--teacher", str(teacher), "-o", str(tmp_path / "runs")],
        "`visualenv distill` takes policy files only",
    )
    assert f"`visualenv export-policy --trust-pickle {teacher} OUT.safetensors`" in output
    assert "pass --trust-pickle" not in output  # distill has no such option
    help_text = CliRunner().invoke(main, ["distill", "--help"]).output
    assert (
        "--trust-pickle" not in help_text
        and "--trust-pickle" in CliRunner().invoke(main, ["export-policy", "-h"]).output
    )


# -- what eval reads beside a policy ----------------------------------------------------------------------------------


def _run_beside(policy, folder, *, eval_episodes=20, results=None, evaluations=(), first_logged=None):
    """The policy in a run folder of the first format (config.json without format_version), state-only."""
    weights = copy_of(policy, folder)
    config = {
        "spec": SPEC,
        "algo": "ppo",
        "steps": 100_000,
        "envs": 1,
        "frame_stack": 1,
        "eval_every": 10_000,
        "eval_episodes": eval_episodes,
        "final_eval_episodes": 5,
        "seed": 0,
        "render": False,
        "hyperparams": {},
        "progress": False,
    }
    (folder / "config.json").write_text(json.dumps({"command": "visualenv train", "config": config}))
    if results is not None:
        (folder / "results.json").write_text(json.dumps(results))
    np.savez(folder / "evaluations.npz", timesteps=np.array(evaluations), results=np.zeros((len(evaluations), 1)))
    if first_logged is not None:
        (folder / "logs").mkdir()
        rows = [[1, first_logged], [2, first_logged + 512]]
        (folder / "logs" / "progress.csv").write_text(
            "time/iterations,time/total_timesteps\n" + "".join(f"{i},{t}\n" for i, t in rows)
        )
    return str(weights)


OLD = {"episodes": 5, "mean_reward": 9.0, "std_reward": 1.0, "mean_length": 9.0, "success_rate": 0.0}


def test_eval_bounds_the_run_beside_the_policy(policy, tmp_path):
    # the case: a config.json that asks for a billion evaluation episodes
    weights = _run_beside(policy, tmp_path / "billion", eval_episodes=1_000_000_000)
    _refused(
        ["eval", SPEC, "--model", weights, "--episodes", "1"],
        "config.json: config.eval_episodes: expected an integer from 1 to 1000000, got 1000000000",
    )
    # a results.json that asks for a billion resets before the replay
    weights = _run_beside(policy, tmp_path / "resets", results={**OLD, "eval_seed": 3, "resets_before": 10**9})
    _refused(
        ["eval", SPEC, "--model", weights, "--episodes", "1"],
        "results.json: resets_before: expected an integer from 0 to 10000, got 1000000000",
    )


def test_an_older_run_whose_replay_would_reset_too_often_is_evaluated_with_a_note(policy, tmp_path):
    from visualenv.train.evaluation import recorded_evaluation

    weights = _run_beside(
        policy, tmp_path / "run", eval_episodes=1_000_000, results=OLD, evaluations=[10_000], first_logged=512
    )
    recorded = recorded_evaluation(tmp_path / "run")
    assert recorded.resets_before == 0 and "are 1,000,002 resets, more than 10,000 replay" in recorded.note
    started = time.perf_counter()
    result = CliRunner().invoke(main, ["eval", SPEC, "--model", weights, "--episodes", "1"])
    assert result.exit_code == 0 and "1 deterministic episodes" in result.output, result.output
    assert time.perf_counter() - started < 60


def test_eval_ignores_an_evaluations_file_that_would_decompress_to_gigabytes(policy, tmp_path):
    from visualenv.train.run_folder import MAX_EVALUATIONS_BYTES, load_evaluations

    folder = tmp_path / "bomb"
    _run_beside(policy, folder, results=OLD)
    np.savez_compressed(folder / "evaluations.npz", timesteps=np.zeros(MAX_EVALUATIONS_BYTES // 8 + 1, np.int64))
    assert (folder / "evaluations.npz").stat().st_size < 2**20 and load_evaluations(folder) is None
