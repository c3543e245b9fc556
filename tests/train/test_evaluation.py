"""The statistics of `visualenv eval` and what it reads from a run folder to replay its final evaluation (no Blender)."""

import csv
import json

import numpy as np
import pytest

from hypothesis import given, strategies as st

from visualenv.train.evaluation import (
    FRESH_SEED,
    bootstrap_mean_interval,
    differences,
    final_seed,
    replays_prefix,
    recorded_evaluation,
    seed_purpose,
    selection_record,
    selection_seed,
    wilson_interval,
)
from visualenv.train.run_folder import legacy_eval_seed
from visualenv.train.run_settings import MAX_TRAIN_SEED

pytestmark = pytest.mark.blender


def test_wilson_interval_matches_the_formula_and_reaches_the_bounds():
    low, high = wilson_interval(42, 50)
    assert low == pytest.approx(0.7149, abs=1e-4) and high == pytest.approx(0.9166, abs=1e-4)
    assert wilson_interval(0, 10)[0] == 0.0 and wilson_interval(0, 10)[1] == pytest.approx(0.2775, abs=1e-4)
    assert wilson_interval(10, 10) == [pytest.approx(0.7225, abs=1e-4), 1.0]


def test_bootstrap_interval_is_reproducible_and_brackets_the_mean():
    values = np.random.default_rng(3).normal(5.0, 2.0, 50)
    low, high = bootstrap_mean_interval(values)
    assert low < values.mean() < high and high - low == pytest.approx(2 * 1.96 * values.std() / np.sqrt(50), rel=0.15)
    assert bootstrap_mean_interval(values) == [low, high]
    assert bootstrap_mean_interval([7.0] * 5) == [7.0, 7.0]


def _run_folder(path, *, results, evaluations=(), first_logged=None, per_iteration=512, eval_episodes=20):
    path.mkdir()
    # an SB3 run of the first format (before pin, batched, workers and render_device)
    config = {
        "spec": "Goalie-v0",
        "algo": "ppo",
        "steps": 100_000,
        "envs": 4,
        "frame_stack": 4,
        "eval_every": 10_000,
        "eval_episodes": eval_episodes,
        "final_eval_episodes": 50,
        "seed": 3,
        "render": True,
        "hyperparams": {"n_steps": 128},
        "progress": False,
    }
    (path / "config.json").write_text(json.dumps({"command": "visualenv train Goalie-v0", "config": config}))
    (path / "results.json").write_text(json.dumps(results))
    np.savez(
        path / "evaluations.npz", timesteps=np.array(evaluations), results=np.zeros((len(evaluations), eval_episodes))
    )
    if first_logged is not None:
        (path / "logs").mkdir()
        with (path / "logs" / "progress.csv").open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["time/fps", "time/iterations", "time/total_timesteps"])
            for i in range(1, 4):
                writer.writerow([30, i, first_logged + (i - 1) * per_iteration])
    return path


OLD_RESULTS = {"episodes": 50, "mean_reward": 6.8, "std_reward": 7.3, "mean_length": 21.4, "success_rate": 0.84}


def test_a_run_that_records_its_eval_seed_is_replayed_from_it(tmp_path):
    run = _run_folder(tmp_path / "run", results={**OLD_RESULTS, "eval_seed": 10_003}, evaluations=[10_000, 20_000])
    recorded = recorded_evaluation(run)
    assert (recorded.seed, recorded.episodes, recorded.resets_before, recorded.frame_stack, recorded.algo) == (
        10_003,
        50,
        0,
        4,
        "ppo",
    )


def test_an_older_run_is_replayed_after_the_resets_of_its_periodic_evaluations(tmp_path):
    # never resumed: the eval env was reset once at the start and 20 + 1 times by each of the 3 periodic evaluations
    run = _run_folder(tmp_path / "fresh", results=OLD_RESULTS, evaluations=[10_000, 20_000, 30_000], first_logged=512)
    recorded = recorded_evaluation(run)
    assert (
        recorded.seed == legacy_eval_seed(3) == 10_003
        and recorded.resets_before == 1 + 3 * 21
        and recorded.note is None
    )
    # resumed at step 36356 (a stop between two evaluations): only the evaluations after it used the final evaluation's env
    run = _run_folder(
        tmp_path / "resumed",
        results=OLD_RESULTS,
        evaluations=[10_000, 20_000, 30_000, 46_356, 56_356, 66_356],
        first_logged=36_868,
    )
    assert recorded_evaluation(run).resets_before == 1 + 3 * 21


def test_an_older_run_without_its_progress_log_is_evaluated_with_a_note(tmp_path):
    run = _run_folder(tmp_path / "run", results=OLD_RESULTS, evaluations=[10_000])
    recorded = recorded_evaluation(run)
    assert recorded.resets_before == 0 and "cannot be counted" in recorded.note
    assert recorded_evaluation(tmp_path) is None  # no config.json: not a run folder


def test_differences_names_each_figure_that_does_not_match():
    assert differences(dict(OLD_RESULTS, reward_ci95=[1, 2]), OLD_RESULTS) == []
    assert differences(dict(OLD_RESULTS, success_rate=0.82), OLD_RESULTS) == ["success_rate 0.82 (results.json: 0.84)"]


@given(run=st.integers(0, MAX_TRAIN_SEED), other=st.integers(0, MAX_TRAIN_SEED), env=st.integers(0, 2**31))
def test_training_selection_and_final_seeds_never_meet(run, other, env):
    """No run's training envs or selection stream start on a seed that any run's final evaluation (or eval's default) uses."""
    trained, picked = run + env, selection_seed(run)
    reported = {final_seed(other), FRESH_SEED}
    assert trained not in reported and picked not in reported and trained != selection_seed(other)
    assert (seed_purpose(trained), seed_purpose(picked), seed_purpose(final_seed(other)), seed_purpose(FRESH_SEED)) == (
        "training",
        "selection",
        "final",
        "fresh",
    )


def test_the_selection_record_is_the_evaluation_that_picked_the_best_model(tmp_path):
    np.savez(
        tmp_path / "evaluations.npz",
        timesteps=np.array([10, 20, 30]),
        results=np.array([[1.0, 3.0], [5.0, 5.0], [5.0, 5.0]]),
        successes=np.array([[0, 1], [1, 0], [1, 1]]),
    )
    record = selection_record(tmp_path, selection_seed(7))
    assert record == {
        "eval_seed": selection_seed(7),
        "evaluations": 3,
        "best_at_step": 20,
        "episodes": 2,
        "mean_reward": 5.0,
        "success_rate": 0.5,
    }
    assert selection_record(tmp_path / "missing", 0) is None


def test_a_shorter_evaluation_is_compared_episode_by_episode_with_the_recorded_ones():
    recorded = {
        "episodes": 4,
        "mean_reward": 1.5,
        "per_episode": {
            "returns": [1.0, 2.0, 1.0, 2.0],
            "lengths": [3, 4, 3, 4],
            "successes": [True, False, True, False],
        },
    }
    same = {"episodes": 2, "per_episode": {"returns": [1.0, 2.0], "lengths": [3, 4], "successes": [True, False]}}
    other = {"episodes": 2, "per_episode": {"returns": [1.0, 3.0], "lengths": [3, 4], "successes": [True, False]}}
    assert replays_prefix(same, recorded) and differences(same, recorded) == []
    assert differences(other, recorded) == ["episode 1: returns 3.0 (results.json: 2.0)"]
    assert not replays_prefix(
        same, {"episodes": 4, "mean_reward": 1.5}
    )  # a results.json without its episodes: no prefix to check


def test_eval_of_random_actions_is_the_seeded_baseline(tmp_path):
    """`eval --model random` plays seeded uniform actions on the state-only env: the same seed gives the same episodes."""
    from click.testing import CliRunner

    from visualenv.cli import main

    def run(seed: int) -> dict:
        out = tmp_path / f"random-{seed}.json"
        result = CliRunner().invoke(
            main,
            ["eval", "LunarLanding-v0", "--model", "random", "--episodes", "30", "--seed", str(seed), "-o", str(out)],
        )
        assert result.exit_code == 0, result.output
        assert "uniform random actions" in result.output
        return json.loads(out.read_text())

    first, again, other = run(7), run(7), run(8)
    assert first["per_episode"] == again["per_episode"] and first["eval_seed"] == 7
    assert first["per_episode"] != other["per_episode"]
    assert first["success_rate"] < 0.2 and 10 < first["mean_length"] < 40  # a random lander mostly crashes


def test_a_policy_acts_on_one_torch_thread_without_onednn_and_torch_is_restored():
    """Torch's idle threads spin on the cores Cycles renders on, and oneDNN's kernels follow the CPU: evaluation runs
    the policy on one thread with oneDNN off, records that MKL was pinned, then sets torch back."""
    torch = pytest.importorskip("torch")
    from visualenv.train.evaluation import evaluate, make_eval_env

    seen = []

    class Recorder:
        def predict(self, obs, deterministic=True):
            seen.append((torch.get_num_threads(), torch.backends.mkldnn.enabled))
            return np.zeros((1, 2), np.float32), None

    torch.set_num_threads(2)
    env = make_eval_env("LunarLanding-v0", seed=0, frame_stack=1, render=False)
    try:
        results = evaluate(Recorder(), env, 2)
    finally:
        env.close()
    assert seen and set(seen) == {(1, False)} and torch.get_num_threads() == 2 and torch.backends.mkldnn.enabled
    assert results["machine"]["cpu_isa"] and results["machine"]["torch"] == torch.__version__
    assert isinstance(results["machine"]["pinned"], bool)


PINNED_FORWARD = """
import contextlib, sys
from visualenv.compat import mkl
# "variable": as `visualenv eval` and `play` pin, MKL_CBWR set before torch loads; "service": as a process visualenv
# did not start is pinned, by MKL's service call before the model is built (its orthogonal init calls MKL)
with mkl.compatible_mode() if sys.argv[1] == "variable" else contextlib.nullcontext():
    import numpy as np, torch
    from stable_baselines3.common.torch_layers import NatureCNN
    from gymnasium import spaces
    from visualenv.train.reproducible import pinned_inference
    mkl.pin()
    net = torch.nn.Sequential(NatureCNN(spaces.Box(0, 255, (4, 100, 100), 'uint8'), 512), torch.nn.Linear(512, 2))
    rng = np.random.default_rng(0)  # weights as a policy file brings them: torch's own init draws by the CPU's vector code
    with torch.no_grad():
        for p in net.parameters():
            p.copy_(torch.from_numpy(rng.normal(0, 0.05, tuple(p.shape))))
    x = torch.from_numpy(rng.random((1, 4, 100, 100), dtype=np.float32))
    with pinned_inference() as pinned, torch.no_grad():
        print(pinned, [v.hex() for v in net(x).double().flatten().tolist()])
"""


def pinned_forward(extra: dict, route: str = "service") -> str:
    """The pinned CNN's output bits in a fresh process, with `extra` in its environment, pinned by `route`."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("ONEDNN_MAX_CPU_ISA", "ATEN_CPU_CAPABILITY", "MKL_CBWR")}
    run = subprocess.run(
        [sys.executable, "-c", PINNED_FORWARD, route], env={**env, **extra}, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    return run.stdout.strip()


@pytest.mark.slow
@pytest.mark.parametrize(
    "dispatch", [{"ONEDNN_MAX_CPU_ISA": "SSE41"}, {"ATEN_CPU_CAPABILITY": "default"}, {"ONEDNN_MAX_CPU_ISA": "AVX2"}]
)
def test_pinned_inference_gives_the_same_bits_whatever_kernels_the_cpu_offers(dispatch):
    """The vector code oneDNN and ATen pick (AVX-512, AVX2, SSE) must not reach a pinned policy's actions: the same
    CNN forward pass, run with each dispatch forced, gives the same bits as with none forced."""
    pytest.importorskip("stable_baselines3")
    plain = pinned_forward({})
    assert plain.startswith("True ")  # MKL was pinned: nothing had called it yet
    assert pinned_forward(dispatch) == plain


@pytest.mark.slow
def test_the_variable_pins_as_the_service_call_does():
    """`visualenv eval` and `play` pin MKL by MKL_CBWR, set before torch loads (visualenv.compat.mkl): the same bits as
    the service call's pinning, with a dispatch forced as well."""
    pytest.importorskip("stable_baselines3")
    by_variable = pinned_forward({}, "variable")
    assert by_variable.startswith("True ")
    assert by_variable == pinned_forward({}, "service") == pinned_forward({"ONEDNN_MAX_CPU_ISA": "SSE41"}, "variable")


def test_a_replay_on_another_machine_is_compared_within_the_stated_tolerance():
    """Elsewhere, the renderer's kernels may move an episode's last digits: outcomes must still match exactly,
    lengths within LENGTH_TOLERANCE steps and returns within RETURN_TOLERANCE."""
    from visualenv.train.evaluation import LENGTH_TOLERANCE, RETURN_TOLERANCE

    recorded = {
        "episodes": 3,
        "mean_reward": 12.0,
        "per_episode": {"returns": [14.3436, 9.0, 12.66], "lengths": [34, 41, 50], "successes": [True, False, True]},
    }
    drift = {
        "episodes": 2,
        "per_episode": {"returns": [14.2855, 9.0], "lengths": [34 + LENGTH_TOLERANCE, 41], "successes": [True, False]},
    }
    assert differences(drift, recorded, tolerant=True) == []
    assert len(differences(drift, recorded)) == 2  # exact: both differences are reported
    assert differences(dict(recorded, episodes=3), recorded, tolerant=True) == []
    assert 15.0 > 14.3436 * (1 + RETURN_TOLERANCE)
    far = {
        "episodes": 2,
        "per_episode": {"returns": [15.0, 9.0], "lengths": [34, 41 + LENGTH_TOLERANCE + 1], "successes": [True, True]},
    }
    assert differences(far, recorded, tolerant=True) == [
        "episode 0: returns 15.0 (results.json: 14.3436)",
        "episode 1: lengths 44 (results.json: 41)",
        "episode 1: successes True (results.json: False)",
    ]


def test_machines_that_differ_in_what_decides_the_last_digits_are_named():
    from visualenv.train.reproducible import machine_record, unlike
    from visualenv.versions import versions

    here = machine_record(True)
    other = (
        "AVX2" if here["cpu_isa"] == "AVX512" else "AVX512"
    )  # whichever ISA this CPU is not: the test holds on either
    assert unlike(here, here) == []
    assert unlike(dict(here, cpu_isa=other), here) == [f"cpu_isa {other} there, {here['cpu_isa']} here"]
    assert unlike(dict(here, cpu="another name"), here) == []  # the model name alone decides nothing
    # two CPUs of one ISA with other vector extensions (Cascade Lake and Emerald Rapids) render in other last bits
    newer = dict(
        here, cpu_features=here["cpu_features"] + " avx10_fake amx_fake"
    )  # flags no CPU has: the test holds on any
    assert unlike(newer, here) == ["cpu_features amx_fake avx10_fake there only, - here only"]
    assert "cpu_features" in here and all(
        f.startswith(("sse", "ssse", "avx", "fma", "f16c", "amx", "vaes", "vpclmulqdq", "gfni", "sha_ni", "bmi", "adx"))
        for f in here["cpu_features"].split()
    )
    assert here["mujoco"] == versions().get("mujoco")  # physics steps differ between MuJoCo versions
    assert unlike(dict(here, mujoco="2.3.7"), here) == [f"mujoco 2.3.7 there, {here['mujoco']} here"]
    assert unlike(None, dict(here, cpu_isa="AVX2")) == [
        "pinned False there, True here"
    ]  # records before machines were kept


def test_episodes_that_cannot_replay_are_compared_as_a_sample():
    """A chaotic agent on another machine plays new episodes: those that could be drawn from results.json's agree, an
    agent that lost its skill does not."""
    from visualenv.train.evaluation import sample_differences

    recorded = {
        "per_episode": {
            "returns": [1000.0] * 54 + [900.0] * 46,
            "lengths": [1000] * 54 + [900] * 46,
            "successes": [True] * 54 + [False] * 46,
        }
    }
    like = {
        "per_episode": {
            "returns": [900.0, 1000.0, 900.0],
            "lengths": [900, 1000, 900],
            "successes": [False, True, False],
        }
    }
    assert sample_differences(like, recorded) == []
    lost = {"per_episode": {"returns": [50.0, 60.0, 70.0], "lengths": [51, 61, 71], "successes": [False] * 3}}
    assert [d.split(" of ")[0] for d in sample_differences(lost, recorded)] == ["returns", "lengths"]
