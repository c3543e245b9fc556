"""`train --resume` reads data: the training state saved as safetensors, JSON and .npz, loaded into a new model, and
the checks made before a run folder is resumed (visualenv/train/checkpoints.py)."""

from __future__ import annotations

import json
import shutil
import zipfile

import gymnasium as gym
import numpy as np
import pytest
import torch
from click.testing import CliRunner

from visualenv.cli import main
from visualenv.train.checkpoints import CheckpointError, load_state, save_state
from visualenv.train.run_folder import STATE_JSON, STATE_REPLAY, STATE_WEIGHTS, RunFolder


def ppo(**kwargs):
    from stable_baselines3 import PPO

    return PPO(
        "MlpPolicy", gym.make("CartPole-v1"), n_steps=32, batch_size=32, n_epochs=2, seed=3, device="cpu", **kwargs
    )


def sac(**kwargs):
    from stable_baselines3 import SAC

    return SAC(
        "MlpPolicy",
        gym.make("Pendulum-v1"),
        buffer_size=500,
        learning_starts=16,
        batch_size=16,
        seed=3,
        device="cpu",
        policy_kwargs={"net_arch": [16]},
        **kwargs,
    )


def same_state(a, b) -> None:
    """Every tensor of the two models' state dicts, optimizers and counters equal."""
    pa, pb = a.get_parameters(), b.get_parameters()
    assert pa.keys() == pb.keys()
    for name in pa:
        flat_a, flat_b = flatten(pa[name]), flatten(pb[name])
        assert flat_a.keys() == flat_b.keys(), name
        for key in flat_a:
            x, y = flat_a[key], flat_b[key]
            assert torch.equal(x, y) if torch.is_tensor(x) else x == y, (name, key)
    for counter in ("num_timesteps", "_n_updates", "_episode_num"):
        assert getattr(a, counter) == getattr(b, counter), counter


def flatten(value, prefix=""):
    if isinstance(value, dict):
        return {k: v for key, item in value.items() for k, v in flatten(item, f"{prefix}/{key}").items()}
    if isinstance(value, (list, tuple)) and not all(isinstance(v, (int, float)) for v in value):
        return {k: v for i, item in enumerate(value) for k, v in flatten(item, f"{prefix}/{i}").items()}
    return {prefix: list(value) if isinstance(value, tuple) else value}


@pytest.mark.parametrize("make", [ppo, sac], ids=["ppo", "sac"])
def test_the_state_round_trips_and_continues_as_sb3s_own_resume(tmp_path, make):
    """A model saved as data and loaded into a new model holds every tensor and counter; trained on, it learns
    exactly what SB3's load of its pickled zip (and replay buffer) learns."""
    algorithm = "ppo" if make is ppo else "sac"
    trained = make()
    trained.learn(64)
    folder = RunFolder(tmp_path)
    save_state(trained, folder, algorithm)
    assert sorted(p.name for p in folder.latest_dir.iterdir()) == sorted(
        [STATE_JSON, STATE_WEIGHTS] + ([STATE_REPLAY] if algorithm == "sac" else [])
    )
    resumed = make()
    load_state(resumed, folder.latest_dir, algorithm)
    same_state(trained, resumed)
    if algorithm == "sac":
        pos = trained.replay_buffer.pos
        assert resumed.replay_buffer.pos == pos == 64 and not resumed.replay_buffer.full
        for field in ("observations", "next_observations", "actions", "rewards", "dones", "timeouts"):
            assert np.array_equal(getattr(resumed.replay_buffer, field), getattr(trained.replay_buffer, field)), field
        assert torch.equal(resumed.log_ent_coef, trained.log_ent_coef)
    resumed.learn(32, reset_num_timesteps=False)  # at once: torch's and numpy's generators are the process's

    trained.save(tmp_path / "sb3.zip")  # SB3's own resume, for comparison: a pickle (this test's own file)
    if algorithm == "sac":
        trained.save_replay_buffer(tmp_path / "buffer.pkl")
    sb3 = type(trained).load(tmp_path / "sb3.zip", env=gym.make(trained.env.envs[0].spec.id), device="cpu")
    if algorithm == "sac":
        sb3.load_replay_buffer(tmp_path / "buffer.pkl")
    sb3.learn(32, reset_num_timesteps=False)
    same_state(sb3, resumed)
    assert resumed.num_timesteps == 96


def test_a_checkpoint_that_does_not_fit_is_an_error(tmp_path):
    folder = RunFolder(tmp_path)
    model = ppo()
    save_state(model, folder, "ppo")
    with pytest.raises(CheckpointError, match="a checkpoint of 'ppo', and this run trains a2c"):
        load_state(model, folder.latest_dir, "a2c")
    with pytest.raises(
        CheckpointError, match=r"policy: mlp_extractor.policy_net.0.weight: expected torch.float32 \[32, 4\]"
    ):
        load_state(ppo(policy_kwargs={"net_arch": [32, 32]}), folder.latest_dir, "ppo")
    state_path = folder.latest_dir / STATE_JSON
    state = json.loads(state_path.read_text())
    for change, message in [
        ({"counters": {**state["counters"], "num_timesteps": -1}}, "counters.num_timesteps: expected a count"),
        ({"format_version": 99}, "format_version 99"),
        ({"episodes": [{"r": "__import__('os')", "l": []}]}, "episodes: expected up to 100"),
    ]:
        state_path.write_text(json.dumps({**state, **change}))
        with pytest.raises(CheckpointError, match=message):
            load_state(ppo(), folder.latest_dir, "ppo")
    groups = json.loads(json.dumps(state["optimizers"]))
    groups["policy.optimizer"]["param_groups"][0]["betas"] = "0.9"
    state_path.write_text(json.dumps({**state, "optimizers": groups}))
    with pytest.raises(CheckpointError, match=r"param_groups\[0\].betas: expected a list of 2"):
        load_state(ppo(), folder.latest_dir, "ppo")
    state_path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(CheckpointError, match="not JSON"):
        load_state(ppo(), folder.latest_dir, "ppo")
    state_path.write_text(json.dumps(state))
    weights = folder.latest_dir / STATE_WEIGHTS
    with weights.open("r+b") as f:  # a file far larger than the model's state: refused from its size, not read
        f.truncate(64 * 2**20)
    with pytest.raises(CheckpointError, match="more than this run's model and optimizers hold"):
        load_state(ppo(), folder.latest_dir, "ppo")


def test_a_replay_buffer_is_checked_from_its_headers_before_it_is_read(tmp_path):
    """An .npz whose header claims a huge array is refused from the header; an object array is never unpickled."""
    folder = RunFolder(tmp_path)
    model = sac()
    model.learn(32)
    save_state(model, folder, "sac")
    replay = folder.latest_dir / STATE_REPLAY
    with np.load(replay) as saved:
        arrays = dict(saved)
    arrays["rewards"] = np.zeros((32, 1), dtype=np.float64)
    np.savez(replay, **arrays)
    with pytest.raises(CheckpointError, match=r"rewards: expected float32 \[32, 1\], got float64 \[32, 1\]"):
        load_state(sac(), folder.latest_dir, "sac")
    arrays["rewards"] = np.array([[object()]] * 32, dtype=object)
    np.savez(replay, **arrays)
    with pytest.raises(CheckpointError, match="rewards: expected float32"):
        load_state(sac(), folder.latest_dir, "sac")
    arrays["rewards"] = np.zeros((32, 1), dtype=np.float32)
    np.savez(replay, **arrays, extra=np.zeros(3))
    with pytest.raises(CheckpointError, match="extra.npy"):
        load_state(sac(), folder.latest_dir, "sac")
    header = np.lib.format.header_data_from_array_1_0(np.zeros((32, 1), np.float32))
    header["shape"] = (2**40, 1)  # a header that claims 4 TiB: refused before numpy allocates it
    with zipfile.ZipFile(replay, "a") as archive, archive.open("huge.npy", "w") as f:
        np.lib.format.write_array_header_1_0(f, header)
    with pytest.raises(CheckpointError, match="huge.npy"):
        load_state(sac(), folder.latest_dir, "sac")


# -- the CLI -----------------------------------------------------------------------------------------------------------

TINY = ["--batched", "2", "--state-only", "--eval-every", "64", "--eval-episodes", "1", "--final-episodes", "1"]
TINY += ["--device", "cpu", "--no-progress"]


@pytest.mark.blender
@pytest.mark.slow
def test_ppo_resumes_from_its_data_checkpoint(tmp_path):
    """A state-only CartPole run (the cheapest: no image, one process) trained, then resumed from its data."""
    out = tmp_path / "runs"
    args = ["train", "VisualCartPole-v0", "--steps", "64", *TINY, "--set", "n_steps=32", "--set", "batch_size=32"]
    result = CliRunner().invoke(main, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    (run,) = (out / "VisualCartPole-v0").iterdir()
    latest = RunFolder(run).latest_dir
    assert (latest / STATE_WEIGHTS).is_file() and not RunFolder(run).latest_zip.exists()
    state = json.loads((latest / STATE_JSON).read_text())
    assert state["counters"]["num_timesteps"] == 64 and state["algorithm"] == "ppo"
    resumed = CliRunner().invoke(
        main, ["train", "VisualCartPole-v0", "--resume", str(run), "--steps", "128", "--no-progress"]
    )
    assert resumed.exit_code == 0, resumed.output
    results = json.loads((run / "results.json").read_text())
    assert results["steps"] == 128 and results["stopped_early"] is False
    assert json.loads((latest / STATE_JSON).read_text())["counters"]["num_timesteps"] == 128
    config = json.loads((run / "config.json").read_text())
    assert config["spec"]["id"] == "VisualCartPole-v0" and len(config["spec"]["sha256"]) == 64 and config["resumes"]
    # a run from before checkpoints were data: SB3's zip, resumed when trusted, which then saves data
    shutil.rmtree(latest)
    shutil.copy(run / "final_model.zip", RunFolder(run).latest_zip)
    older = ["train", "VisualCartPole-v0", "--resume", str(run), "--steps", "192", "--no-progress", "--trust-pickle"]
    trusted = CliRunner().invoke(main, older)
    assert trusted.exit_code == 0, trusted.output
    assert json.loads((latest / STATE_JSON).read_text())["counters"]["num_timesteps"] == 192


@pytest.mark.blender
@pytest.mark.slow
def test_sac_resumes_with_its_replay_buffer(tmp_path):
    out = tmp_path / "runs"
    args = ["train", "LunarLanding-v0", "--algo", "sac", "--steps", "64", *TINY, "--out", str(out)]
    args += ["--set", "learning_starts=32", "--set", "buffer_size=200", "--set", "batch_size=16"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    (run,) = (out / "LunarLanding-v0").iterdir()
    latest = RunFolder(run).latest_dir
    with np.load(latest / STATE_REPLAY) as replay:
        assert replay["observations"].shape[:2] == (32, 2)  # 64 steps of 2 envs: 32 rows
    resumed = CliRunner().invoke(
        main, ["train", "LunarLanding-v0", "--resume", str(run), "--steps", "96", "--no-progress"]
    )
    assert resumed.exit_code == 0, resumed.output
    state = json.loads((latest / STATE_JSON).read_text())
    assert state["counters"]["num_timesteps"] == 96 and state["replay_buffer"] == {"pos": 48, "full": False}


@pytest.fixture
def run(tmp_path):
    """A run folder as `train` leaves it, without the training: config.json, results.json, final model files."""
    from dataclasses import asdict

    from visualenv.env.registration import resolve
    from visualenv.spec.loader import spec_identity
    from visualenv.train.run_folder import write_config, write_results
    from visualenv.train.sb3 import TrainConfig

    folder = RunFolder(tmp_path / "run")
    folder.path.mkdir()
    config = TrainConfig("VisualCartPole-v0", steps=64, render=False, hyperparams={"n_steps": 32}, progress=False)
    spec = resolve("VisualCartPole-v0")
    record = {"backend": "sb3", "command": "visualenv train", "config": asdict(config), "versions": {}}
    write_config(folder, {**record, "spec_path": str(spec), "spec": spec_identity(spec)})  # as record_run writes it
    figures = {"episodes": 1, "mean_reward": 200.0, "std_reward": 0.0, "mean_length": 200.0, "success_rate": 1.0}
    write_results(folder, {**figures, "eval_seed": 7})
    for name in ("final_model.zip", "final_model.safetensors", "final_model.json"):
        (folder.path / name).write_text(f"{name} as trained\n")
    return folder.path


def untouched(run):
    """Every file of a run folder and its bytes: a refused resume leaves them as they were."""
    return {str(p.relative_to(run)): p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()}


def hostile_zip(path, marker):
    """An SB3-shaped zip whose data, once unpickled (as SB3's load does), creates `marker`."""
    import base64
    import pickle
    import zipfile

    class Payload:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    payload = base64.b64encode(pickle.dumps(Payload())).decode()
    data = {"policy_class": {":type:": "<class 'abc.ABCMeta'>", ":serialized:": payload}}
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("data", json.dumps(data))


def test_a_pickled_checkpoint_is_refused_without_trust_pickle(run, tmp_path):
    from stable_baselines3.common.save_util import load_from_zip_file

    marker = tmp_path / "ran"
    hostile_zip(RunFolder(run).latest_zip, marker)
    before = untouched(run)
    result = CliRunner().invoke(main, ["train", "VisualCartPole-v0", "--resume", str(run), "--no-progress"])
    assert result.exit_code == 1 and "latest.zip is an SB3 model: a pickle-based file" in result.output, result.output
    assert "pass --trust-pickle" in result.output and "Traceback" not in result.output
    assert not marker.exists() and untouched(run) == before
    load_from_zip_file(RunFolder(run).latest_zip)  # what SB3's load would have done: the file is hostile
    assert marker.exists()


def test_trust_pickle_is_only_for_resuming(tmp_path):
    result = CliRunner().invoke(main, ["train", "VisualCartPole-v0", "--trust-pickle", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "--trust-pickle: only with --resume" in result.output
    assert not list(tmp_path.iterdir())


def test_a_folder_without_a_checkpoint_or_of_another_spec_is_refused(run, tmp_path):
    from visualenv.env.registration import resolve

    save_state(ppo(), RunFolder(run), "ppo")
    before = untouched(run)
    other = CliRunner().invoke(main, ["train", "Hover2D-v0", "--resume", str(run), "--no-progress"])
    assert other.exit_code == 1 and "was trained on VisualCartPole-v0" in other.output, other.output
    assert "hover2d.yaml (Hover2D-v0, sha256" in other.output
    edited = tmp_path / "cartpole.yaml"
    edited.write_text(resolve("VisualCartPole-v0").read_text() + "\n# edited\n")
    changed = CliRunner().invoke(main, ["train", str(edited), "--resume", str(run), "--no-progress"])
    assert changed.exit_code == 1 and "on another version of VisualCartPole-v0" in changed.output, changed.output
    assert untouched(run) == before
    shutil.rmtree(RunFolder(run).latest_dir.parent)
    before = untouched(run)
    none = CliRunner().invoke(main, ["train", "VisualCartPole-v0", "--resume", str(run), "--no-progress"])
    assert none.exit_code == 1 and "has no checkpoint to resume from" in none.output, none.output
    assert untouched(run) == before
    for result in (other, changed, none):
        assert "Traceback" not in result.output and isinstance(result.exception, SystemExit)


@pytest.mark.blender
def test_a_resumed_run_evaluates_at_the_runs_own_steps_and_counts_all_its_time(tmp_path):
    """Evaluations fall every --eval-every steps from the run's start, a resumed segment's too, and once more at a last
    step between them; results.json's time is the run's in all."""
    out = tmp_path / "runs"
    args = ["train", "VisualCartPole-v0", "--steps", "96", *TINY, "--set", "n_steps=16", "--set", "batch_size=32"]
    result = CliRunner().invoke(main, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    (run,) = (out / "VisualCartPole-v0").iterdir()
    assert np.load(run / "evaluations.npz")["timesteps"].tolist() == [64, 96]  # 96 falls between evaluations
    first = json.loads((run / "results.json").read_text())
    assert "segment_wall_time_s" not in first
    saved = json.loads((RunFolder(run).latest_dir / STATE_JSON).read_text())["wall_time_s"]
    assert 0 < saved <= first["wall_time_s"]
    resumed = CliRunner().invoke(
        main, ["train", "VisualCartPole-v0", "--resume", str(run), "--steps", "192", "--no-progress"]
    )
    assert resumed.exit_code == 0, resumed.output
    # 128 and 192, as a run never stopped; counted from the resume they would be 160 and 192
    assert np.load(run / "evaluations.npz")["timesteps"].tolist() == [64, 96, 128, 192]
    results = json.loads((run / "results.json").read_text())
    assert results["wall_time_s"] == pytest.approx(saved + results["segment_wall_time_s"], abs=0.2)
    assert f"192 steps in {results['wall_time_s']:.0f} s (" in resumed.output
