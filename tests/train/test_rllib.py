"""The Ray RLlib backend: env registration, frame stacking in the runners, train --backend rllib, play, stop and resume.

Runs where the [ray] extra is installed (``make setup`` installs it); that importing visualenv never imports
Ray is tested in test_layers.py, which runs everywhere.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from visualenv.cli import main
from visualenv.train.evaluation import final_seed, selection_seed

pytestmark = pytest.mark.blender

REPO = Path(__file__).resolve().parents[2]


ray = pytest.importorskip("ray.rllib", reason="the [ray] extra is not installed")


def tiny_goalie(tmp_path: Path, size: int = 24) -> str:
    """Goalie-v0 at a few pixels: renders in a millisecond or two (the runner tests sample many steps)."""
    from visualenv.env.registration import resolve

    text = (
        resolve("Goalie-v0")
        .read_text()
        .replace("resolution: [100, 100]", f"resolution: [{size}, {size}]")
        .replace("id: Goalie-v0", "id: TinyGoalie-v0")
    )
    assert f"[{size}, {size}]" in text
    path = tmp_path / "tiny_goalie.yaml"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("size", [(100, 100), (100, 120), (24, 24), (6, 6)])
def test_conv_filters_are_sized_from_the_observation(size):
    """Every image size ends in NatureCNN's 512 features, one dense layer that both heads read."""
    from ray.rllib.core.models.configs import CNNEncoderConfig

    from visualenv.train.rllib_setup import FEATURES, conv_filters

    encoder = CNNEncoderConfig(input_dims=(*size, 4), cnn_filter_specifiers=conv_filters(*size))
    assert encoder.output_dims == (FEATURES,)
    if size == (
        100,
        100,
    ):  # RLlib's own defaults stop at 84x84: sizing the filters is what lets the paper's 100x100 through
        from ray.rllib.models.utils import get_filter_config

        with pytest.raises(ValueError, match="No default CNN configuration"):
            get_filter_config((100, 100, 4))


def test_the_image_model_is_sb3s_nature_cnn_initialised_as_sb3_does():
    """RLlib's default (PyTorch's) initialisation gave Goalie features that hardly varied with the image; SB3's orthogonal one does not."""
    import torch
    from gymnasium import spaces
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from visualenv.train.rllib_setup import model_config

    space = spaces.Box(0.0, 1.0, (100, 100, 4), np.float32)
    module = RLModuleSpec(
        module_class=DefaultPPOTorchRLModule,
        observation_space=space,
        action_space=spaces.Discrete(2),
        model_config=model_config(space),
    ).build()
    assert (
        sum(p.numel() for p in module.parameters()) == 2_734_243
    )  # SB3's CnnPolicy on (4, 100, 100) with 2 actions: the same count
    convolutions = [m for m in module.modules() if isinstance(m, torch.nn.Conv2d)]
    assert len(convolutions) == 4
    for conv in convolutions:
        rows = conv.weight.detach().flatten(1)
        gram = rows @ rows.T if rows.shape[0] <= rows.shape[1] else rows.T @ rows
        assert torch.allclose(gram, 2 * torch.eye(len(gram)), atol=1e-4)  # orthogonal, gain sqrt(2)


def test_evaluations_fall_at_the_first_iteration_past_each_multiple_of_eval_every():
    from visualenv.train.rllib import evaluation_due

    evaluated, last = [], 0
    for steps in range(100, 1001, 100):  # iterations of 100 steps, evaluations every 128
        if evaluation_due(last, steps, 128):
            evaluated.append(steps)
            last = steps
    # one at the first iteration past each of 128, 256, ..., 896 (128 steps since the last one gave 200, 400, ...)
    assert evaluated == [200, 300, 400, 600, 700, 800, 900]
    assert not evaluation_due(300, 380, 128) and evaluation_due(300, 384, 128)  # a resumed run's count goes on


def test_default_ppo_is_sb3s_and_the_hyperparameter_file_says_so(tmp_path):
    """RLlib's own PPO clips the value loss at 10 and adds a KL penalty; the backend runs SB3's PPO, and its file says so."""
    import yaml

    from visualenv.train.rllib_setup import SB3_PPO_DEFAULTS, ppo_config

    assert yaml.safe_load((REPO / "examples/hyperparams/goalie-rllib.yaml").read_text()) == {
        k: v for k, v in SB3_PPO_DEFAULTS.items() if k != "grad_clip_by"
    }
    config = ppo_config(tiny_goalie(tmp_path))
    assert config.vf_clip_param == float("inf") and config.use_kl_loss is False and config.grad_clip == 0.5
    assert ppo_config(tiny_goalie(tmp_path), hyperparams={"use_kl_loss": True}).use_kl_loss is True


def test_runner_env_stacks_four_scaled_frames():
    """The driver's own env (a plain config, no remote worker index) stacks scaled frames and leaves the process's
    cores alone: only Ray's remote EnvRunners claim one."""
    from visualenv.train.rllib_setup import make_rllib_env

    ours = os.sched_getaffinity(0)
    env = make_rllib_env({"spec": "Goalie-v0", "frame_stack": 4})
    assert os.sched_getaffinity(0) == ours
    try:
        assert env.observation_space.shape == (100, 100, 4) and env.observation_space.dtype == np.float32
        obs, _ = env.reset(seed=0)
        assert obs.dtype == np.float32 and 0.0 <= obs.min() and obs.max() <= 1.0
        assert obs[..., 3].std() > 0.02  # a rendered field, not a blank frame
        assert not obs[..., :3].any()  # reset zeroes the older slots, as SB3's VecFrameStack does
        for _ in range(3):
            obs, *_ = env.step(1)
        assert not np.array_equal(
            obs[..., 0], obs[..., 3]
        )  # the goalie moved: the newest frame differs from the oldest
    finally:
        env.close()


REMOTE_RUNNER_ENV = """
import os
from ray.rllib.env.env_context import EnvContext
from visualenv.train.rllib_setup import make_rllib_env
env = make_rllib_env(EnvContext({"spec": "VisualCartPole-v0", "frame_stack": 1}, worker_index=1))
print(sorted(os.sched_getaffinity(0)))
env.close()
"""


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="confinement shows only where there are two cores")
def test_a_remote_runners_env_confines_its_process_to_one_core(tmp_path):
    env = {**os.environ, "TMPDIR": str(tmp_path)}  # the claims' lock files of this process alone
    done = subprocess.run(
        [sys.executable, "-c", REMOTE_RUNNER_ENV], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert len(json.loads(done.stdout.strip().splitlines()[-1])) == 1


def test_observations_the_encoder_cannot_take_are_refused_before_anything_starts(tmp_path):
    from visualenv.env.registration import resolve

    spec = tmp_path / "two_cameras.yaml"
    spec.write_text(
        resolve("Goalie-v0")
        .read_text()
        .replace(
            "  camera: Camera\n  resolution: [100, 100]\n  color: grayscale\n",
            "  cameras:\n    front: {camera: Camera, resolution: [64, 64]}\n    back: {camera: Camera, resolution: [64, 64]}\n",
        )
    )
    result = CliRunner().invoke(main, ["train", str(spec), "--backend", "rllib", "--out", str(tmp_path / "runs")])
    assert (
        result.exit_code == 1
        and "RLlib's default encoder has no Dict support" in result.output
        and "Traceback" not in result.output
    )
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--address", "127.0.0.1:1"], "--address 127.0.0.1:1: cannot reach a Ray head there"),
        (["--address", "nohost"], "expected HOST:PORT of a Ray head"),
        (["--set", "learning_rate=1e-4"], "RLlib's PPO has no hyperparameter 'learning_rate'"),
        (["--envs", "4"], "--envs: not for --backend rllib"),
    ],
)
def test_bad_rllib_runs_are_refused_with_one_line(tmp_path, args, message):
    result = CliRunner().invoke(
        main, ["train", "Goalie-v0", "--backend", "rllib", "--out", str(tmp_path / "runs"), *args]
    )
    assert result.exit_code in (1, 2) and message in result.output and "Traceback" not in result.output, result.output
    assert not (tmp_path / "runs").exists()


def test_a_checkpoint_of_another_model_is_refused_with_one_line(tmp_path):
    """--resume of a run whose checkpoint holds another model (an older visualenv's, say) names the run, not torch's traceback."""
    from visualenv.errors import ConfigError
    from visualenv.train.rllib import _restore

    class OtherModel:
        def restore_from_path(self, path: str) -> None:
            raise RuntimeError(
                "Error(s) in loading state_dict for DefaultPPOTorchRLModule:\n\tsize mismatch for pi.net.mlp.0.weight"
            )

    latest = tmp_path / "checkpoints" / "latest"
    latest.mkdir(parents=True)
    (latest / "visualenv.json").write_text('{"steps": 1024}')
    with pytest.raises(
        ConfigError, match=r"cannot resume .*does not fit this run's model.*size mismatch for pi.net.mlp.0.weight"
    ):
        _restore(OtherModel(), tmp_path)
    fits = type("Fits", (), {"restore_from_path": lambda self, path: None})()
    assert _restore(fits, tmp_path) == (1024, 0.0)  # a checkpoint from before the time was recorded
    (latest / "visualenv.json").write_text('{"steps": 1024, "wall_time_s": 61.5}')
    assert _restore(fits, tmp_path) == (1024, 61.5)
    (latest / "visualenv.json").write_text('{"steps": 1024, "wall_time_s": "a minute"}')
    assert _restore(fits, tmp_path) == (1024, 0.0)  # an edited time counts as none, not a traceback
    for edited in ("1e999", "-5", "1" + "0" * 400):  # infinite, negative, an integer no float holds
        (latest / "visualenv.json").write_text(f'{{"steps": 1024, "wall_time_s": {edited}}}')
        assert _restore(fits, tmp_path) == (1024, 0.0), edited


def test_a_resumed_run_keeps_its_backend(tmp_path):
    config = {
        "spec": "Goalie-v0",
        "algo": "ppo",
        "steps": 1000,
        "envs": 2,
        "frame_stack": 4,
        "eval_every": 500,
        "eval_episodes": 2,
        "final_eval_episodes": 2,
        "seed": 0,
        "render": True,
        "hyperparams": {},
        "progress": False,
    }
    # an SB3 run before format 2: no 'backend' key
    (tmp_path / "config.json").write_text(json.dumps({"config": config}))
    result = CliRunner().invoke(main, ["train", "Goalie-v0", "--backend", "rllib", "--resume", str(tmp_path)])
    assert result.exit_code == 2 and "was trained with --backend sb3; a resumed run keeps its backend" in result.output


def test_an_rllib_checkpoint_resumes_only_with_trust_pickle(tmp_path):
    """RLlib's checkpoint folders are pickles: --resume refuses one untrusted, and a run without one, before anything
    starts or is written."""
    from dataclasses import asdict

    from visualenv.env.registration import resolve
    from visualenv.train.rllib import RLlibTrainConfig
    from visualenv.spec.loader import spec_identity
    from visualenv.train.run_folder import RunFolder, write_config

    folder = RunFolder(tmp_path / "run")
    folder.path.mkdir()
    spec = resolve("Goalie-v0")
    config = asdict(RLlibTrainConfig("Goalie-v0", steps=128, progress=False))
    record = {"backend": "rllib", "command": "visualenv train", "config": config, "versions": {}}
    write_config(folder, {**record, "spec_path": str(spec), "spec": spec_identity(spec)})
    before = folder.config.read_bytes()
    none = CliRunner().invoke(main, ["train", "Goalie-v0", "--resume", str(folder.path), "--no-progress"])
    assert none.exit_code == 1 and "has no checkpoint to resume from (no checkpoints/latest)" in none.output, (
        none.output
    )
    folder.latest_dir.mkdir(parents=True)
    (folder.latest_dir / "visualenv.json").write_text('{"steps": 64}')
    refused = CliRunner().invoke(main, ["train", "Goalie-v0", "--resume", str(folder.path), "--no-progress"])
    assert refused.exit_code == 1 and "is an RLlib checkpoint folder: a pickle-based file" in refused.output
    assert "pass --trust-pickle" in refused.output and folder.config.read_bytes() == before
    assert sorted(p.name for p in folder.path.iterdir()) == ["checkpoints", "config.json"]


def test_runner_options_need_the_rllib_backend(tmp_path):
    result = CliRunner().invoke(main, ["train", "Goalie-v0", "--env-runners", "3", "--out", str(tmp_path / "runs")])
    assert result.exit_code == 2 and "--env-runners: only with --backend rllib" in result.output


@pytest.mark.slow
def test_each_runner_renders_and_the_driver_runner_makes_no_env(tmp_path):
    import ray

    from visualenv.train.rllib_setup import ppo_config

    ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        algo = ppo_config(tiny_goalie(tmp_path), env_runners=1, envs_per_runner=2).build_algo()
        try:
            assert algo.env_runner.env is None  # the driver's own EnvRunner: a model copy, no env, so no Blender

            def sample_and_look(runner):
                episodes = runner.sample(num_timesteps=8, random_actions=True)
                frames = np.concatenate([np.asarray(e.get_observations()) for e in episodes])
                return sum(len(e) for e in episodes), "bpy" in sys.modules, runner.env.observation_space.shape, frames

            (sampled,) = algo.env_runner_group.foreach_env_runner(sample_and_look, local_env_runner=False)
            steps, blender, shape, frames = sampled
            assert (
                steps >= 8 and blender and shape == (2, 24, 24, 4)
            )  # two envs of four stacked frames, made in the runner
            # the runner's observations are Blender's 8-bit images, scaled to 0..1 as the encoder takes them: a lit scene, and the ball moves
            levels = frames[..., -1] * 255
            assert np.allclose(levels, np.round(levels), atol=1e-3) and 0 <= levels.min() and levels.max() <= 255
            assert levels.max() - levels.min() > 40 and not np.array_equal(levels[0], levels[-1])
        finally:
            algo.stop()
    finally:
        ray.shutdown()


@pytest.mark.slow
def test_a_batched_runner_steps_its_envs_in_one_blender_scene(tmp_path):
    """--batched N with --backend rllib: each runner owns one BatchedVectorEnv of N envs (Gymnasium's vector entry point)."""
    import ray

    from visualenv.train.rllib_setup import ppo_config

    ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        algo = ppo_config(tiny_goalie(tmp_path), env_runners=1, envs_per_runner=3, batched=True).build_algo()
        try:
            (sampled,) = algo.env_runner_group.foreach_env_runner(
                lambda r: (
                    sum(len(e) for e in r.sample(num_timesteps=30, random_actions=True)),
                    type(r.env.unwrapped).__name__,
                    r.env.observation_space.shape,
                    r.env.unwrapped.renderer.n,
                ),
                local_env_runner=False,
            )
            steps, kind, shape, rendered = sampled
            assert steps >= 30 and kind == "BatchedVectorEnv" and shape == (3, 24, 24, 4) and rendered == 3
        finally:
            algo.stop()
    finally:
        ray.shutdown()


def test_vector_frame_stack_restarts_the_stack_of_an_env_that_reset():
    from visualenv.env.batch import BatchedVectorEnv
    from visualenv.env.wrappers import VectorFrameStack

    vec = VectorFrameStack(BatchedVectorEnv("Goalie-v0", 2), 4)
    try:
        obs, _ = vec.reset(seed=0)
        assert obs.shape == (2, 100, 100, 4) and not obs[..., :3].any() and obs[..., 3].std() > 1
        done = np.zeros(2, dtype=bool)
        for _ in range(80):
            obs, _, terminated, truncated, _ = vec.step(np.array([0, 1]))
            if done.any():  # this step reset the env that ended: its older slots are zero again
                assert not obs[done][..., :3].any()
                return
            done = terminated | truncated
        pytest.fail("no episode ended")
    finally:
        vec.close()


TRAIN = [
    "--backend",
    "rllib",
    "--env-runners",
    "2",
    "--eval-every",
    "64",
    "--eval-episodes",
    "1",
    "--final-episodes",
    "2",
    "--set",
    "train_batch_size_per_learner=64",
    "--set",
    "minibatch_size=32",
    "--set",
    "num_epochs=1",
    "--no-progress",
]


@pytest.mark.slow
@pytest.mark.timeout(600)  # two Ray starts and a dozen iterations: 105-192 s measured on the loaded 2-core VM
def test_rllib_run_stops_on_sigterm_saves_and_resumes(tmp_path):
    """A run stopped with SIGTERM still saves, evaluates and plots; --resume continues its steps and evaluations."""
    spec, out = tiny_goalie(tmp_path), tmp_path / "runs"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen(
        [sys.executable, "-m", "visualenv.cli", "train", spec, "--steps", "100000", "--out", str(out), *TRAIN],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    deadline = time.monotonic() + 240
    progress = None
    while time.monotonic() < deadline and process.poll() is None:
        runs = list((out / "TinyGoalie-v0").glob("*/logs/progress.csv")) if out.exists() else []
        if runs and len(runs[0].read_text().splitlines()) >= 3:  # two iterations: one evaluation and checkpoint done
            progress = runs[0]
            break
        time.sleep(1)
    assert progress is not None, (
        process.communicate(timeout=60)[0] if process.poll() is not None else "no progress in 240 s"
    )
    process.send_signal(signal.SIGTERM)
    output = process.communicate(timeout=240)[0]
    assert process.returncode == 0, output
    run = progress.parents[1]
    for name in [
        "config.json",
        "results.json",
        "evaluations.npz",
        "logs/progress.csv",
        "plots/rewards.png",
        "plots/lengths.png",
        "plots/success.png",
        "plots/fps.png",
        "best_model",
        "final_model",
        "checkpoints/latest",
        "best_model.safetensors",
        "best_model.json",
        "final_model.safetensors",
        "final_model.json",
    ]:
        assert (run / name).exists(), name
    results = json.loads((run / "results.json").read_text())
    assert results["stopped_early"] is True and results["episodes"] == 2 and 64 <= results["steps"] < 100000
    assert "segment_wall_time_s" not in results  # a run of one segment
    assert json.loads((run / "config.json").read_text())["backend"] == "rllib"
    # the best model was picked on one seed stream and is reported on another, as in the SB3 backend
    assert results["selection"]["eval_seed"] == selection_seed(0) and results["eval_seed"] == final_seed(0)
    assert results["selection"]["evaluations"] >= 1 and results["selection"]["episodes"] == 1
    with np.load(run / "evaluations.npz") as first:
        evaluated = first["timesteps"].tolist()
    assert evaluated
    assert f"eval at {evaluated[0]} steps: mean return " in output  # --no-progress: a line per evaluation

    assert (
        results["model"] == "best_model.safetensors"
    )  # the final evaluation read the policy file train wrote: no pickle
    played = CliRunner().invoke(main, ["play", spec, "--model", str(run / "best_model.safetensors"), "--episodes", "1"])
    assert played.exit_code == 0 and "episode 0: return" in played.output, played.output
    replayed = CliRunner().invoke(
        main, ["eval", spec, "--model", str(run / results["model"])]
    )  # the final evaluation again
    assert replayed.exit_code == 0 and "reproduces its run's results.json" in replayed.output, replayed.output
    refused = CliRunner().invoke(
        main, ["play", spec, "--model", str(run / "best_model"), "--episodes", "1"]
    )  # the checkpoint: a pickle
    assert refused.exit_code == 1 and "is an RLlib checkpoint folder: a pickle-based file" in refused.output, (
        refused.output
    )
    exported = CliRunner().invoke(
        main, ["export-policy", "--trust-pickle", str(run / "best_model"), str(tmp_path / "policy.safetensors")]
    )
    assert exported.exit_code == 0 and "float16 weights" in exported.output, exported.output  # how results/ ships one
    from visualenv.train.model_files import load_model

    full, small = load_model(run / "best_model", trust_pickle=True), load_model(tmp_path / "policy.safetensors")
    ours = load_model(
        run / "best_model.safetensors"
    )  # train's float32 policy file: the policy the checkpoint holds, exactly
    import torch

    scaled = {
        "obs": torch.as_tensor(np.random.default_rng(1).random((8, *full.observation_space.shape), dtype=np.float32))
    }
    with torch.no_grad():
        assert torch.equal(
            full.module.forward_inference(scaled)["action_dist_inputs"],
            ours.module.forward_inference(scaled)["action_dist_inputs"],
        )
    frames = np.random.default_rng(0).integers(0, 256, (8, *full.observation_space.shape), dtype=np.uint8)
    assert (full.predict(frames)[0] == small.predict(frames)[0]).mean() >= 0.75  # float16 weights: near-ties may flip

    stopped_at = results["steps"]
    resumed = CliRunner().invoke(
        main, ["train", spec, "--resume", str(run), "--steps", str(stopped_at + 128), "--no-progress", "--trust-pickle"]
    )  # an RLlib checkpoint is a pickle: resumed only when trusted
    assert resumed.exit_code == 0, resumed.output
    results = json.loads((run / "results.json").read_text())
    assert results["steps"] >= stopped_at + 128 and results["stopped_early"] is False
    with np.load(run / "evaluations.npz") as later:
        assert later["timesteps"].tolist()[: len(evaluated)] == evaluated and len(later["timesteps"]) > len(
            evaluated
        )  # history kept
        assert later["timesteps"][-1] == results["steps"]  # and the model as training left it evaluated
    assert results["wall_time_s"] > results["segment_wall_time_s"] > 0  # the stopped segment's time counted too
    steps = [int(line.split(",")[0]) for line in (run / "logs" / "progress.csv").read_text().splitlines()[1:]]
    assert steps == sorted(steps) and steps[-1] == results["steps"]  # the resumed run carried on the step count


def _descendants() -> list:
    import psutil

    return psutil.Process().children(recursive=True)


def _runner_processes() -> list:
    return [p for p in _descendants() if _cmdline(p).startswith("ray::SingleAgentEnvRunner")]


def _cmdline(process) -> str:
    import psutil

    try:
        return " ".join(process.cmdline())
    except psutil.Error:
        return ""


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_two_node_cluster_samples_on_both_and_survives_a_killed_runner(tmp_path):
    """Two Ray nodes on this machine, one runner on each (one CPU per node); one runner is killed mid-run.

    RLlib restarts it and the run reaches its steps with every evaluation checkpointed;
    afterwards no runner (each held a Blender) or Ray process is left.
    """
    import psutil
    from ray.cluster_utils import Cluster

    spec, out = tiny_goalie(tmp_path), tmp_path / "runs"
    earlier = {
        p.pid for p in _descendants()
    }  # e.g. this process's multiprocessing resource tracker, from earlier tests
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    try:
        worker = cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "visualenv.cli",
                "train",
                spec,
                "--steps",
                "512",
                "--address",
                cluster.address,
                "--out",
                str(out),
                "--backend",
                "rllib",
                "--env-runners",
                "2",
                "--eval-every",
                "128",
                "--eval-episodes",
                "1",
                "--final-episodes",
                "1",
                "--set",
                "train_batch_size_per_learner=64",
                "--set",
                "minibatch_size=32",
                "--set",
                "num_epochs=1",
                "--no-progress",
            ],
            cwd=REPO,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        deadline, killed, replaced = time.monotonic() + 300, None, False
        while not replaced and time.monotonic() < deadline and process.poll() is None:
            progress = list(out.glob("*/*/logs/progress.csv")) if out.exists() else []
            if killed is None and progress and len(progress[0].read_text().splitlines()) >= 3:
                runners = _runner_processes()
                assert len(runners) == 2, [_cmdline(p) for p in runners]
                first_pids = {p.pid for p in runners}
                killed = runners[0].pid
                runners[0].kill()
            elif killed is not None:
                replaced = any(p.pid not in first_pids for p in _runner_processes())  # RLlib started a new runner
            time.sleep(0.5)
        output = process.communicate(timeout=400)[0]
        assert killed is not None and replaced and process.returncode == 0, output
        (run,) = out.glob("*/*")
        results = json.loads((run / "results.json").read_text())
        assert results["steps"] >= 512 and not results["stopped_early"]
        by_node = json.loads((run / "logs" / "env_steps_by_node.json").read_text())
        assert set(by_node) == {cluster.head_node.node_id, worker.node_id} and min(by_node.values()) > 0, by_node
        with np.load(run / "evaluations.npz") as evaluations:
            timesteps = evaluations["timesteps"].tolist()
        # an evaluation (and checkpoint) at each iteration that passed a multiple of 128, none lost to the kill and
        # none drifting off them; then, where the last step fell between them, the final model's
        progress = (run / "logs" / "progress.csv").read_text().splitlines()[1:]
        iterations = [int(line.split(",")[0]) for line in progress]
        due = [after for before, after in zip([0, *iterations], iterations) if after // 128 > before // 128]
        assert len(due) >= 512 // 128 and iterations[-1] == results["steps"], iterations
        assert timesteps == (due if due[-1] == results["steps"] else [*due, results["steps"]]), (timesteps, iterations)
        assert json.loads((run / "checkpoints" / "latest" / "visualenv.json").read_text())["steps"] == results["steps"]
        assert (
            not (run / "checkpoints" / "latest.old").exists() and not (run / "checkpoints" / "latest.saving").exists()
        )
    finally:
        cluster.shutdown()
    deadline = time.monotonic() + 30

    def left_over() -> list[str]:
        return [
            _cmdline(p)
            for p in _descendants()
            if p.pid not in earlier and p.is_running() and p.status() != psutil.STATUS_ZOMBIE
        ]

    while time.monotonic() < deadline and left_over():
        time.sleep(0.5)
    left = left_over()
    assert not left, left
