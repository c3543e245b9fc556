"""`visualenv train`: PPO (or another SB3 algorithm) from pixels, as in the paper.

A run folder ``runs/<Id>/<timestamp>/`` holds everything a run makes (:mod:`visualenv.train.run_folder` lists
it): the command and settings, the logs, the periodic evaluations, the best and final models as SB3 zips and as
policy files (float32 weights, which ``eval`` and ``play`` load without unpickling), the training state for
``--resume`` as data (:mod:`visualenv.train.checkpoints`), the plots, and results.json: the best policy file's final
evaluation on fresh seeds and the periodic evaluation that selected it (see :mod:`visualenv.train.evaluation`).

Stopping a run early (Ctrl-C, or ``kill`` with SIGTERM) ends training at the next
step and still saves, evaluates and plots what was learnt so far.

A run evaluates every ``eval_every`` steps counted from its start, a resumed one too, and once more at its last step
when that falls between evaluations, so the curve ends where training did and the final model can be the best.
results.json's ``wall_time_s`` is the run's training time in all: a resumed run adds the time its checkpoint had
recorded (the time after that checkpoint, redone on resuming, is not counted) and gives its own segment's as
``segment_wall_time_s``.
"""

from __future__ import annotations

import sys
import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

from visualenv.env.cores import usable_cores
from visualenv.errors import ConfigError, did_you_mean
from visualenv.train.evaluation import (
    declares_success,
    FINAL_EPISODES,
    evaluation_line,
    final_evaluation,
    final_seed,
    make_eval_env,
    selection_record,
    selection_seed,
)
from visualenv.train.config_checks import (
    check_cnn_input,
    check_replay_buffer,
    check_target_pace,
    check_torch_device,
)
from visualenv.train.checkpoints import load_state, resume_checkpoint, save_state, saved_wall_time, sb3_checkpoint
from visualenv.train.model_files import algorithm_class, load_model, save_policy
from visualenv.train.stopping import StopRequest
from visualenv.train.run_folder import RunClock, RunFolder, read_config, record_run, write_results
from visualenv.train.policy_kinds import named_classes

SCHEDULES = ("learning_rate", "clip_range", "clip_range_vf")  # hyperparameters SB3 takes as a number or a schedule
SET_BY_TRAIN = ("policy", "env", "seed", "verbose", "tensorboard_log", "_init_setup_model")  # not hyperparameters


@dataclass
class TrainConfig:
    spec: str
    algo: str = "ppo"
    steps: int = 200_000
    envs: int = 2
    frame_stack: int = 4
    eval_every: int = 10_000  # env steps between evaluations
    eval_episodes: int = 10
    final_eval_episodes: int = FINAL_EPISODES
    seed: int = 0
    render: bool = True  # False: state-only env and an MLP policy
    hyperparams: dict[str, Any] = field(default_factory=dict)
    progress: bool = True
    pin: bool = True  # each training env's process confined to its own cores
    batched: bool = False  # the envs in one process and one Blender (BatchedVectorEnv) instead of one process each
    workers: int | None = None  # with batched: the envs split into this many batches, one process each
    render_device: str | None = None  # "cpu" or "gpu": where the training envs render (None: the spec's render.device)
    augment: str | None = None  # "shift": DrQ's random shift of the image observations (visualenv.train.drq)

    def policy(self, observation_space: Any) -> str:
        """SB3's policy for the env: images through a CNN, several cameras through one CNN each, a state vector through an MLP."""
        from gymnasium import spaces

        if isinstance(observation_space, spaces.Dict):
            return "MultiInputPolicy"
        return "CnnPolicy" if self.render else "MlpPolicy"


def algorithm_kwargs(algo: str, hyperparams: dict[str, Any], augment: str | None = None) -> dict[str, Any]:
    """`hyperparams` as keyword arguments of the SB3 algorithm, checked before any env starts.

    A misspelt name is an error listing the algorithm's names (SB3's ``load``
    would set it silently). Schedules use rl-zoo's syntax: ``lin_3e-4`` decays
    linearly from 3e-4 to 0 over the run.
    """
    import inspect

    from stable_baselines3.common.utils import LinearSchedule

    algorithm = algorithm_class(algo, augment)
    parameters = {
        **inspect.signature(algorithm_class(algo).__init__).parameters,
        **inspect.signature(algorithm.__init__).parameters,  # DrQ's SAC: SAC's and its own
    }
    known = [n for n in parameters if n not in ("self", "args", "kwargs") and n not in SET_BY_TRAIN]
    kwargs: dict[str, Any] = {}
    for key, value in hyperparams.items():
        if key not in known:
            if augment is None and key in inspect.signature(algorithm_class(algo, "shift").__init__).parameters:
                raise ConfigError(f"{key} is a hyperparameter of DrQ's {algo.upper()}: train with --augment shift")
            raise ConfigError(f"{algo.upper()} has no hyperparameter '{key}'" + did_you_mean(key, known))
        default = parameters[key].default
        if isinstance(value, str) and isinstance(default, (int, float)) and key not in SCHEDULES:
            raise ConfigError(
                f"{key}: expected a {'true/false' if isinstance(default, bool) else 'number'} (default {default}), got {value!r}"
            )
        if key in SCHEDULES and not isinstance(value, (int, float)) and value is not None:
            text = str(value)
            try:
                start = float(text.removeprefix("lin_")) if text.startswith("lin_") else None
            except ValueError:
                start = None
            if start is None:
                raise ConfigError(
                    f"{key}: expected a number or a linear schedule such as lin_3e-4 (from 3e-4 down to 0), got {text!r}"
                )
            value = LinearSchedule(start, 0.0, 1.0)
        kwargs[key] = named_classes(value) if key == "policy_kwargs" else value
    return kwargs


def resumed_config(
    config_class: Any,
    run_dir: Path,
    *,
    steps: int | None,
    hyperparams: dict[str, Any],
    progress: bool,
    spec: str | None = None,
) -> Any:
    """The configuration of the run in `run_dir`, carried on: its settings as saved, with the total steps (if given),
    the changed hyperparameters and the progress display of this command, and `spec` (which training checks is the
    run's) where given. Used by both backends (`config_class`)."""
    record = read_config(run_dir)
    if record["backend"] not in ("sb3", "rllib"):
        raise ConfigError(
            f"{run_dir} is a run of `visualenv {record['backend']}`, which `visualenv train` cannot resume"
        )
    saved = record["config"]
    return config_class(
        **{
            **saved,
            "spec": spec or saved["spec"],
            "steps": steps or saved["steps"],
            "hyperparams": {**saved["hyperparams"], **hyperparams},
            "progress": progress,
        }
    )


def _vec_kwargs(config: TrainConfig) -> dict[str, Any]:
    if not config.render:
        return {"render": False}
    return {"device": config.render_device} if config.render_device else {}


def train(
    config: TrainConfig,
    run_dir: Path,
    *,
    resume: bool = False,
    changes: dict[str, Any] | None = None,
    trust_code: bool = False,
    trust_pickle: bool = False,
) -> dict[str, Any]:
    """Train, evaluate the best model, draw the plots; returns the final results.

    A resumed run continues from its checkpoint (an older run's pickled ``checkpoints/latest.zip`` only with
    `trust_pickle`), once it is known to be a run of `config`'s spec; `changes` are hyperparameters that differ
    from the saved model's from now on (recorded in config.json under ``resumes``).
    `trust_code`: the spec's ``dynamics.python`` may be imported, in every env process (docs/security.md); it is the
    caller's consent, never read from or written to the run folder.
    """
    from visualenv.env.registration import resolve

    spec_path = str(resolve(config.spec))
    changes = dict(changes or {})
    kwargs, changed_kwargs = check_config(config, changes)
    folder = RunFolder(run_dir)
    checkpoint = None
    if resume:  # checked before anything in the folder is written
        found = sb3_checkpoint(folder)
        checkpoint = resume_checkpoint(folder, spec_path, found, backend="sb3", trust_pickle=trust_pickle)
    run_dir.mkdir(parents=True, exist_ok=True)
    record_run(folder, config, spec_path, backend="sb3", resume=resume, changes=changes)
    if resume:
        folder.keep_earlier_progress()
    train_env, eval_env = _make_envs(config, spec_path, folder, resume, trust_code)
    clock = RunClock(earlier=saved_wall_time(checkpoint) if checkpoint is not None else 0.0)
    stopper = _StopOnSignal()
    try:
        model = _make_model(config, train_env, checkpoint, kwargs, changed_kwargs)
        _learn(model, config, eval_env, folder, stopper, resume, clock)
    except BaseException:
        eval_env.close()
        raise
    finally:
        train_env.close()
    return _finish(model, config, eval_env, folder, clock=clock, resumed=resume, stopped_early=stopper.requested)


def _make_envs(
    config: TrainConfig, spec_path: str, folder: RunFolder, resume: bool, trust_code: bool = False
) -> tuple[Any, Any]:
    """The training envs (subprocesses, one Blender each) and the evaluation env, which renders once now to fail early."""
    from visualenv.env.sb3_vec import make_sb3_batched, make_sb3_vec

    frame_stack = config.frame_stack if config.render else 0
    vec_options = dict(seed=config.seed, frame_stack=frame_stack, pin=config.pin, **_vec_kwargs(config))
    vec_options.update(monitor_dir=str(folder.monitor), monitor_append=resume)
    if trust_code:  # given to each env's process with the other options
        vec_options["trust_code"] = True
    if config.batched:
        train_env = make_sb3_batched(spec_path, config.envs, workers=config.workers, **vec_options)
    else:
        train_env = make_sb3_vec(spec_path, config.envs, **vec_options)
    try:
        eval_env = make_eval_env(
            spec_path,
            seed=selection_seed(config.seed),
            frame_stack=frame_stack,
            render=config.render,
            trust_code=trust_code,
        )
        eval_env.reset()  # render now: a broken eval env fails here, not after the first eval_every steps
    except BaseException:
        train_env.close()
        raise
    return train_env, eval_env


def _make_model(
    config: TrainConfig, train_env: Any, checkpoint: Path | None, kwargs: dict[str, Any], changed_kwargs: dict[str, Any]
) -> Any:
    """A new model; for a resumed run, with the checkpoint's state loaded into it (the run's hyperparameters, changes
    included, build it), or an older run's trusted zip with the changed hyperparameters set before it is built."""
    from visualenv.train.drq import model_arguments
    from visualenv.train.encoders import channels_last

    algo = algorithm_class(config.algo, config.augment)
    pickled = checkpoint is not None and not checkpoint.is_dir()
    if pickled:
        try:
            model = algo.load(checkpoint, env=train_env, **changed_kwargs)
        except Exception as exc:  # SB3 raises whatever its unpickling met
            raise ConfigError(f"cannot resume from {checkpoint}: {type(exc).__name__}: {exc}") from None
    else:
        policy, extra = model_arguments(config.algo, config.augment, config.policy(train_env.observation_space))
        try:
            model = algo(policy, train_env, seed=config.seed, verbose=0, **kwargs, **extra)
        except (TypeError, ValueError, AssertionError) as exc:  # SB3 checks its arguments with all three
            raise ConfigError(
                f"{config.algo.upper()} cannot take these hyperparameters ({config.hyperparams}): {exc}"
            ) from None
    channels_last(model.policy)  # before a data checkpoint's state: its weights are copied into this layout
    if checkpoint is not None and not pickled:
        load_state(model, checkpoint, config.algo)
    return model


def _learn(
    model: Any,
    config: TrainConfig,
    eval_env: Any,
    folder: RunFolder,
    stopper: _StopOnSignal,
    resume: bool,
    clock: RunClock,
) -> None:
    """Learn up to config.steps with periodic evaluation, checkpoints and the progress bar; evaluate the last step's
    model where no periodic evaluation fell; save the latest and final models."""
    from stable_baselines3.common.callbacks import CallbackList
    from stable_baselines3.common.logger import configure

    model.set_logger(configure(str(folder.logs), ["csv", "tensorboard"]))
    per_env = max(1, config.eval_every // config.envs)
    evaluation = _ResumableEval(
        eval_env,
        n_eval_episodes=config.eval_episodes,
        eval_freq=per_env,
        log_path=str(folder.path),
        best_model_save_path=str(folder.path),
        deterministic=True,
        verbose=0,
        callback_after_eval=None if config.progress else _EvalLine(declares_success(config.spec)),
        callback_on_new_best=_BestPolicy(folder, config.algo),
    )
    callbacks = [evaluation, _LatestCheckpoint(folder, config.algo, per_env, clock), _PhaseThreads(), stopper]
    done = model.num_timesteps if resume else 0
    if config.progress:
        callbacks.append(_ProgressBar(config.steps, done))
    with stopper.listening(), warnings.catch_warnings():
        # one eval env runs in-process (DummyVecEnv), the training envs in subprocesses: same env, different wrapper
        warnings.filterwarnings("ignore", message="Training and eval env are not of the same type")
        model.learn(
            total_timesteps=max(0, config.steps - done),
            callback=CallbackList(callbacks),
            reset_num_timesteps=not resume,
        )
    if not stopper.requested:
        evaluation.evaluate_last()
    save_state(model, folder, config.algo, wall_time_s=clock.elapsed())
    model.save(folder.final_zip)
    save_policy(model, folder.final_policy, half=False, algorithm=config.algo, run_dir=folder.path)


def _finish(
    model: Any,
    config: TrainConfig,
    eval_env: Any,
    folder: RunFolder,
    *,
    clock: RunClock,
    resumed: bool,
    stopped_early: bool,
) -> dict[str, Any]:
    """The best policy file's final evaluation (closing the eval env), results.json and the plots."""
    from visualenv.train.plots import training_plots

    wall, segment = clock.elapsed(), clock.segment()  # training's time, without the final evaluation

    evaluated = folder.best_policy if folder.best_policy.exists() else folder.final_policy
    try:
        results = final_evaluation(load_model(evaluated), eval_env, config.final_eval_episodes, final_seed(config.seed))
    finally:
        eval_env.close()
    results.update(
        {
            "selection": selection_record(folder.path, selection_seed(config.seed)),
            "steps": int(model.num_timesteps),
            "wall_time_s": round(wall, 1),
            "model": evaluated.name,
            "stopped_early": stopped_early,
        }
    )
    if resumed:
        results["segment_wall_time_s"] = round(segment, 1)
    write_results(folder, results)
    training_plots(folder.path)
    return results


def check_config(config: TrainConfig, changes: dict[str, Any] | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """What can be wrong with a run before any env starts; the algorithm's keyword arguments (all, and the changed ones)."""
    from visualenv.env.registration import resolve
    from visualenv.spec import load_spec
    from visualenv.train.drq import check_augment

    kwargs, changed = (
        algorithm_kwargs(config.algo, config.hyperparams, config.augment),
        algorithm_kwargs(config.algo, changes or {}, config.augment),
    )
    both = {**kwargs, **changed}
    check_torch_device(both.get("device", "auto"))
    loaded = load_spec(resolve(config.spec))
    if config.render:
        check_cnn_input(loaded, both.get("policy_kwargs"))
    check_augment(config.augment, config.algo, config.render, loaded)
    check_replay_buffer(config, both, loaded)
    check_target_pace(config, both)
    return kwargs, changed


def _count_from_run_start(callback: BaseCallback) -> None:
    """Set `callback`'s call count to the vector steps the run has taken, so a resumed run's periodic work falls at
    the steps an uninterrupted run's does (SB3 counts calls from each ``learn``)."""
    callback.n_calls = callback.model.num_timesteps // callback.training_env.num_envs


class _ResumableEval(EvalCallback):
    """SB3's EvalCallback that, in a resumed run, carries on the earlier evaluations at the run's own steps.

    Without this a resumed run would forget its history (evaluations.npz is
    rewritten from scratch) and its best score, so the first evaluation after a
    resume would overwrite a better best_model.zip.
    """

    def _on_training_start(self) -> None:
        _count_from_run_start(self)

    def evaluate_last(self) -> None:
        """Evaluate the model as learning left it, unless the last periodic evaluation was at this step."""
        done = self.model.num_timesteps
        if self.evaluations_timesteps and self.evaluations_timesteps[-1] == done:
            return
        self.num_timesteps = done
        self.n_calls = (self.n_calls // self.eval_freq + 1) * self.eval_freq  # due now
        self._on_step()

    def _init_callback(self) -> None:
        super()._init_callback()
        path = Path(self.log_path + ".npz") if self.log_path else None
        if path is None or not path.exists() or self.evaluations_timesteps:
            return
        with np.load(path) as earlier:
            self.evaluations_timesteps = earlier["timesteps"].tolist()
            self.evaluations_results = earlier["results"].tolist()
            self.evaluations_length = earlier["ep_lengths"].tolist()
            if "successes" in earlier:
                self.evaluations_successes = earlier["successes"].tolist()
        if self.evaluations_results:
            self.best_mean_reward = float(max(np.mean(r) for r in self.evaluations_results))


class _EvalLine(BaseCallback):
    """Without the progress bar, one line per evaluation on stdout: its steps, mean return and (where the spec declares
    a success) its successes."""

    def __init__(self, succeeds: bool) -> None:
        super().__init__()
        self.succeeds = succeeds

    def _on_step(self) -> bool:
        parent = self.parent
        if isinstance(parent, EvalCallback) and parent.evaluations_results:
            successes = (
                parent.evaluations_successes[-1]
                if self.succeeds and len(parent.evaluations_successes) == len(parent.evaluations_results)
                else None
            )
            print(
                evaluation_line(parent.evaluations_timesteps[-1], parent.evaluations_results[-1], successes), flush=True
            )
        return True


class _LatestCheckpoint(BaseCallback):
    """Replace the one checkpoint (data, :func:`~visualenv.train.checkpoints.save_state`), so a killed run resumes from
    its last save."""

    def __init__(self, folder: RunFolder, algorithm: str, every: int, clock: RunClock):
        super().__init__()
        self.folder, self.algorithm, self.every, self.clock = folder, algorithm, every, clock

    def _on_training_start(self) -> None:
        _count_from_run_start(self)

    def _on_step(self) -> bool:
        if self.n_calls % self.every == 0:
            save_state(self.model, self.folder, self.algorithm, wall_time_s=self.clock.elapsed())
        return True


class _BestPolicy(BaseCallback):
    """On each new best evaluation, the model as the best policy file too (beside EvalCallback's best_model.zip): the
    final evaluation reads it, and no pickle."""

    def __init__(self, folder: RunFolder, algorithm: str):
        super().__init__()
        self.folder, self.algorithm = folder, algorithm

    def _on_step(self) -> bool:
        save_policy(self.model, self.folder.best_policy, half=False, algorithm=self.algorithm, run_dir=self.folder.path)
        return True


class _PhaseThreads(BaseCallback):
    """Torch on one thread while the env workers render, on every core while the policy learns.

    During roll-outs the Blender workers need the cores and the policy only runs
    small batches; during the update the workers wait. Logs each phase's time
    (``time/rollout_s``, ``time/update_s``) so the split can be seen.
    """

    def __init__(self) -> None:
        super().__init__()
        self.cores = len(usable_cores())
        self.mark: float | None = None

    def _on_rollout_start(self) -> None:
        import torch

        now = time.perf_counter()
        if self.mark is not None:
            self.logger.record("time/update_s", round(now - self.mark, 2))
        self.mark = now
        torch.set_num_threads(1)

    def _on_rollout_end(self) -> None:
        import torch

        now = time.perf_counter()
        if self.mark is not None:
            self.logger.record("time/rollout_s", round(now - self.mark, 2))
        self.mark = now
        torch.set_num_threads(self.cores)

    def _on_step(self) -> bool:
        return True


class _StopOnSignal(BaseCallback):
    """Turn SIGINT/SIGTERM into a clean stop, so an interrupted run still gets its evaluation and plots (a second
    Ctrl-C aborts)."""

    def __init__(self) -> None:
        super().__init__()
        self.stop = StopRequest("this step")

    @property
    def requested(self) -> bool:
        return self.stop.requested

    @contextmanager
    def listening(self) -> Iterator[None]:
        with self.stop.listening():
            yield
        if self.requested:
            print(f"stopped early at {self.model.num_timesteps} steps; evaluating the best model", file=sys.stderr)

    def _on_step(self) -> bool:
        return not self.requested


class _ProgressBar(BaseCallback):
    """A tqdm bar over env steps showing the recent mean episode reward and length."""

    def __init__(self, total: int, done: int):
        super().__init__()
        self.total, self.done = total, done
        self.bar: Any = None

    def _on_training_start(self) -> None:
        from tqdm import tqdm

        self.bar = tqdm(total=self.total, initial=self.done, unit="step", dynamic_ncols=True, smoothing=0.05)

    def _on_step(self) -> bool:
        assert self.bar is not None
        self.bar.update(self.model.num_timesteps - self.bar.n)
        buffer = self.model.ep_info_buffer
        if buffer and self.n_calls % 20 == 0:
            self.bar.set_postfix(
                reward=f"{np.mean([e['r'] for e in buffer]):.1f}", length=f"{np.mean([e['l'] for e in buffer]):.0f}"
            )
        return True

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()
