"""`visualenv train --backend rllib`: PPO on a Ray cluster, writing the SB3 backend's run folder.

The run folder has the layout :mod:`visualenv.train.sb3` describes, with RLlib
checkpoint folders in place of SB3's zip files: ``best_model/``,
``final_model/`` and ``checkpoints/latest/`` (each a full Algorithm checkpoint,
pickles, which ``--resume`` reads back only with ``--trust-pickle``), and the policies of
the first two as policy files, ``best_model.safetensors`` and ``final_model.safetensors``
(each with its ``.json``), which ``eval`` and ``play`` load without unpickling. ``logs/progress.csv`` uses SB3's
column names, ``evaluations.npz`` EvalCallback's arrays, and the plots and
``results.json`` are drawn and computed by the same code as the SB3 backend's
(:func:`visualenv.train.plots.training_plots`, :func:`visualenv.train.evaluation.final_evaluation`).
The evaluation env runs in the driver, as SB3's does, so the driver renders only
while it evaluates; the runners sample on the cluster.

``logs/env_steps_by_node.json`` counts the env steps sampled on each Ray node.
Not written: ``monitor/`` (RLlib's runners may be on other machines; their
episode returns are in progress.csv) and TensorBoard events.
"""

from __future__ import annotations

import csv
import json
import shutil
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from visualenv.train.evaluation import FINAL_EPISODES, declares_success, evaluation_line
from visualenv.train.run_folder import (
    CHECKPOINT_STEPS,
    RunClock,
    RunFolder,
    record_run,
    recorded_seconds,
    write_results,
)
from visualenv.train.stopping import StopRequest

BACKEND = "rllib"
PROGRESS_COLUMNS = (
    "time/total_timesteps",
    "time/iterations",
    "time/fps",
    "time/time_elapsed",
    "rollout/ep_rew_mean",
    "rollout/ep_len_mean",
    "rollout/success_rate",
    "train/learning_rate",
    "train/policy_loss",
    "train/value_loss",
    "train/entropy",
)


@dataclass
class RLlibTrainConfig:
    spec: str
    steps: int = 200_000
    env_runners: int = 2
    envs_per_runner: int = 1
    frame_stack: int = 4
    eval_every: int = 10_000  # env steps between evaluations (and checkpoints)
    eval_episodes: int = 10
    final_eval_episodes: int = FINAL_EPISODES
    seed: int = 0
    render: bool = True
    hyperparams: dict[str, Any] = field(default_factory=dict)
    progress: bool = True
    pin: bool = True  # each EnvRunner claims a core of its node of its own
    batched: bool = False  # each EnvRunner's envs in one Blender scene (BatchedVectorEnv)
    algo: str = "ppo"
    backend: str = BACKEND


def algorithm_config(config: RLlibTrainConfig, trust_code: bool = False) -> Any:
    """The PPOConfig of this run; checks the spec and the hyperparameters before anything starts.

    `trust_code`: the spec's ``dynamics.python`` may be imported (the caller's consent, not part of the run's config).
    """
    from visualenv.train.rllib_setup import ppo_config

    return ppo_config(
        config.spec,
        env_runners=config.env_runners,
        envs_per_runner=config.envs_per_runner,
        frame_stack=config.frame_stack if config.render else 0,
        seed=config.seed,
        render=config.render,
        hyperparams=config.hyperparams,
        pin=config.pin,
        batched=config.batched,
        trust_code=trust_code,
    )


@contextmanager
def ray_cluster(address: str | None, cpus: int) -> Iterator[None]:
    """Connect to the cluster at `address`, or start a local one of `cpus` CPUs; shut down what this started."""
    import ray

    if ray.is_initialized():
        yield
        return
    kwargs: dict[str, Any] = {
        "include_dashboard": False,
        "log_to_driver": False,
        "configure_logging": True,
        "logging_level": "ERROR",
    }
    if address:
        ray.init(address=address, **kwargs)
    else:
        ray.init(address="local", num_cpus=cpus, **kwargs)  # "local": a new cluster, even where `ray start` runs one
    try:
        yield
    finally:
        ray.shutdown()


def save_checkpoint(algo: Any, path: Path, steps: int, wall_time_s: float | None = None) -> None:
    """Save to a sibling folder, then swap it in: a run killed while saving keeps its previous checkpoint.
    `wall_time_s`: the run's training time so far, which a resumed run adds to its own."""
    fresh, old = path.with_name(path.name + ".saving"), path.with_name(path.name + ".old")
    shutil.rmtree(fresh, ignore_errors=True)
    algo.save_to_path(str(fresh.resolve()))
    record = {"steps": int(steps)} | ({} if wall_time_s is None else {"wall_time_s": round(wall_time_s, 1)})
    (fresh / CHECKPOINT_STEPS).write_text(json.dumps(record) + "\n")
    if path.exists():
        shutil.rmtree(old, ignore_errors=True)
        path.rename(old)
    fresh.rename(path)
    shutil.rmtree(old, ignore_errors=True)


def latest_checkpoint(run_dir: Path) -> Path | None:
    """checkpoints/latest, or the one it was replacing when a save was interrupted."""
    latest = RunFolder(run_dir).latest_dir
    for path in (latest, latest.with_name(latest.name + ".old")):
        if (path / CHECKPOINT_STEPS).is_file():
            return path
    return None


class _Evaluations:
    """evaluations.npz as SB3's EvalCallback writes it (timesteps, results, ep_lengths, successes), carried over a resume."""

    def __init__(self, path: Path):
        self.path = path
        self.timesteps: list[int] = []
        self.results: list[list[float]] = []
        self.ep_lengths: list[list[int]] = []
        self.successes: list[list[bool]] = []
        if path.exists():
            with np.load(path) as earlier:
                self.timesteps = earlier["timesteps"].tolist()
                self.results = earlier["results"].tolist()
                self.ep_lengths = earlier["ep_lengths"].tolist()
                self.successes = earlier["successes"].tolist() if "successes" in earlier else []

    @property
    def best(self) -> float:
        return max((float(np.mean(r)) for r in self.results), default=-np.inf)

    def add(self, steps: int, returns: list[float], lengths: list[int], successes: list[bool]) -> None:
        self.timesteps.append(steps)
        self.results.append(returns)
        self.ep_lengths.append(lengths)
        self.successes.append(successes)
        np.savez(
            self.path,
            timesteps=self.timesteps,
            results=self.results,
            ep_lengths=self.ep_lengths,
            successes=self.successes,
        )


def _episodes(policy: Any, vec_env: Any, episodes: int) -> tuple[list[float], list[int], list[bool]]:
    """Per-episode returns, lengths and successes of deterministic episodes (SB3's evaluate_policy, through our policy)."""
    from stable_baselines3.common.evaluation import evaluate_policy

    successes: list[bool] = []

    def record(local: dict[str, Any], _: Any) -> None:
        if local["done"]:
            successes.append(bool(local["info"].get("is_success", False)))

    returns, lengths = evaluate_policy(
        policy,
        vec_env,
        n_eval_episodes=episodes,
        deterministic=True,
        return_episode_rewards=True,
        callback=record,
        warn=False,
    )
    assert isinstance(returns, list) and isinstance(lengths, list)  # return_episode_rewards=True: one entry per episode
    return [float(r) for r in returns], [int(n) for n in lengths], successes[:episodes]


def _progress_row(result: dict[str, Any], steps: int, elapsed: float, iteration_steps: int) -> dict[str, Any]:
    runners, learner = result.get("env_runners", {}), result.get("learners", {}).get("default_policy", {})
    seconds = result.get("time_this_iter_s") or 0.0
    return {
        "time/total_timesteps": steps,
        "time/iterations": result.get("training_iteration"),
        "time/time_elapsed": round(elapsed, 1),
        "time/fps": round(iteration_steps / seconds) if seconds else "",
        "rollout/ep_rew_mean": runners.get("episode_return_mean", ""),
        "rollout/ep_len_mean": runners.get("episode_len_mean", ""),
        "rollout/success_rate": runners.get("success_rate", ""),
        "train/learning_rate": learner.get("default_optimizer_learning_rate", ""),
        "train/policy_loss": learner.get("policy_loss", ""),
        "train/value_loss": learner.get("vf_loss", ""),
        "train/entropy": learner.get("entropy", ""),
    }


def _count_nodes(path: Path, result: dict[str, Any]) -> None:
    """Env steps sampled on each Ray node over the run (node id -> steps): where the rendering happened."""
    by_node = json.loads(path.read_text()) if path.exists() else {}
    for node, steps in (result.get("env_runners", {}).get("env_steps_by_node") or {}).items():
        if np.isfinite(steps):  # NaN: the node's runner sent nothing this iteration (it died, or is starting)
            by_node[node] = by_node.get(node, 0) + int(steps)
    path.write_text(json.dumps(by_node, indent=2) + "\n")


def _append_progress(path: Path, row: dict[str, Any]) -> None:
    new = not path.exists()
    with path.open("a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=PROGRESS_COLUMNS)
        if new:
            writer.writeheader()
        writer.writerow({k: ("" if v is None or (isinstance(v, float) and np.isnan(v)) else v) for k, v in row.items()})


def train(
    config: RLlibTrainConfig,
    run_dir: Path,
    *,
    resume: bool = False,
    changes: dict[str, Any] | None = None,
    address: str | None = None,
    trust_code: bool = False,
    trust_pickle: bool = False,
) -> dict[str, Any]:
    """Train on the cluster at `address` (a local one if None), evaluate the best model, draw the plots; the final results.

    `trust_code`: the spec's ``dynamics.python`` may be imported, in every EnvRunner too (docs/security.md). A resumed
    run continues from its checkpoint folder, a pickle: only with `trust_pickle`, once the run is known to be one of
    `config`'s spec."""
    from visualenv.train.plots import training_plots
    from visualenv.env.registration import resolve
    from visualenv.train.checkpoints import resume_checkpoint
    from visualenv.train.model_files import load_model
    from visualenv.train.rllib_setup import check_address
    from visualenv.env.cores import usable_cores
    from visualenv.train.evaluation import final_evaluation, final_seed, make_eval_env, selection_record, selection_seed

    check_address(address)
    algo_config = algorithm_config(config, trust_code)
    folder = RunFolder(run_dir)
    if resume:  # checked before anything in the folder is written
        checkpoint = latest_checkpoint(run_dir)
        resume_checkpoint(folder, resolve(config.spec), checkpoint, backend=BACKEND, trust_pickle=trust_pickle)
    run_dir.mkdir(parents=True, exist_ok=True)
    folder.logs.mkdir(exist_ok=True)
    frame_stack = config.frame_stack if config.render else 0
    eval_env = make_eval_env(
        config.spec,
        seed=selection_seed(config.seed),
        frame_stack=frame_stack,
        render=config.render,
        transpose=False,
        trust_code=trust_code,
    )
    stop = StopRequest()
    cpus = max(len(usable_cores()), config.env_runners)  # a local cluster: one CPU per runner even on a small machine
    try:
        with ray_cluster(address, cpus):
            algo = algo_config.build_algo()
            try:
                steps, earlier = _restore(algo, run_dir) if resume else (0, 0.0)
                record_run(folder, config, str(resolve(config.spec)), backend=BACKEND, resume=resume, changes=changes)
                results = _train_loop(config, folder, algo, eval_env, stop, steps, RunClock(earlier))
            finally:
                algo.stop()
        model = folder.best_policy if folder.best_policy.exists() else folder.final_policy
        results.update(
            final_evaluation(load_model(model), eval_env, config.final_eval_episodes, final_seed(config.seed))
        )
    finally:
        eval_env.close()
    results["model"] = model.name
    results["selection"] = selection_record(run_dir, selection_seed(config.seed))
    segment = results.pop("segment_wall_time_s")
    results = {
        k: results[k]
        for k in (
            "episodes",
            "mean_reward",
            "std_reward",
            "mean_length",
            "success_rate",
            "reward_ci95",
            "length_ci95",
            "success_ci95",
            "ci_method",
            "eval_seed",
            "selection",
            "steps",
            "wall_time_s",
            "model",
            "stopped_early",
        )
    }
    if resume:
        results["segment_wall_time_s"] = segment
    write_results(folder, results)
    training_plots(run_dir)
    return results


def _restore(algo: Any, run_dir: Path) -> tuple[int, float]:
    """Load the run's latest checkpoint into `algo`; the steps it had trained and the time it took (0 where an older
    checkpoint did not record it). A checkpoint of another model is refused."""
    from visualenv.errors import ConfigError

    earlier = latest_checkpoint(run_dir)
    if earlier is None:
        return 0, 0.0
    try:
        algo.restore_from_path(str(earlier.resolve()))
    # RLlib raises whatever torch or its unpickling met; a model of another shape is the usual one
    except Exception as exc:
        detail = " ".join(str(exc).split())[:300]
        raise ConfigError(
            f"cannot resume {run_dir}: its checkpoint does not fit this run's model (saved by another version of "
            f"visualenv or with other settings?): {detail}"
        ) from None
    record = json.loads((earlier / CHECKPOINT_STEPS).read_text())
    return int(record["steps"]), recorded_seconds(record.get("wall_time_s"))


def evaluation_due(last_eval: int, steps: int, every: int) -> bool:
    """Whether an iteration that brought the run to `steps` passed a multiple of `every` the last evaluation (at
    `last_eval`) had not: evaluations at the first iteration past each multiple, never drifting off them, however
    many steps an iteration samples."""
    return steps // every > last_eval // every


def _train_loop(
    config: RLlibTrainConfig,
    folder: RunFolder,
    algo: Any,
    eval_env: Any,
    stop: StopRequest,
    steps: int,
    clock: RunClock,
) -> dict[str, Any]:
    """Train to config.steps, evaluating at the first iteration past each multiple of `eval_every` (counted from the
    run's start, a resumed run's too) and at a last step between evaluations (as the SB3 backend does); save the
    latest, best and final checkpoints."""
    from tqdm import tqdm

    from visualenv.train.model_files import save_rllib_module
    from visualenv.train.rllib_setup import RLlibPolicy

    evaluations = _Evaluations(folder.evaluations)
    succeeds = declares_success(config.spec)
    last_eval = evaluations.timesteps[-1] if evaluations.timesteps else steps
    latest = folder.latest_dir
    latest.parent.mkdir(exist_ok=True)

    def evaluate() -> None:
        returns, lengths, successes = _episodes(RLlibPolicy(algo.get_module()), eval_env, config.eval_episodes)
        improved = float(np.mean(returns)) > evaluations.best
        evaluations.add(steps, returns, lengths, successes)
        if not config.progress:
            print(evaluation_line(steps, returns, successes if succeeds else None), flush=True)
        if improved:
            save_checkpoint(algo, folder.best_dir, steps)
            save_rllib_module(algo.get_module(), folder.best_policy, half=False, run_dir=folder.path)

    bar = tqdm(total=config.steps, initial=steps, unit="step", dynamic_ncols=True, disable=not config.progress)
    with stop.listening(), bar:
        while steps < config.steps and not stop.requested:
            result = algo.train()
            sampled = int(result.get("env_runners", {}).get("num_env_steps_sampled", 0))
            steps += sampled
            _count_nodes(folder.env_steps_by_node, result)
            row = _progress_row(result, steps, clock.segment(), sampled)
            _append_progress(folder.progress, row)
            bar.update(steps - bar.n)
            reward = row["rollout/ep_rew_mean"]
            bar.set_postfix(
                reward=f"{reward:.1f}" if reward != "" else "-",
                runners=result.get("fault_tolerance", {}).get("num_healthy_workers", "?"),
            )
            if evaluation_due(last_eval, steps, config.eval_every):
                last_eval = steps
                evaluate()
                save_checkpoint(algo, latest, steps, clock.elapsed())
    if stop.requested:
        print(f"stopped early at {steps} steps", file=sys.stderr)
    elif steps > 0 and (not evaluations.timesteps or evaluations.timesteps[-1] != steps):
        evaluate()
    save_checkpoint(algo, latest, steps, clock.elapsed())
    save_checkpoint(algo, folder.final_dir, steps, clock.elapsed())
    save_rllib_module(algo.get_module(), folder.final_policy, half=False, run_dir=folder.path)
    return {
        "steps": steps,
        "wall_time_s": round(clock.elapsed(), 1),
        "segment_wall_time_s": round(clock.segment(), 1),
        "stopped_early": stop.requested,
    }
