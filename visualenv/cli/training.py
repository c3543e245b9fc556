"""`visualenv train`: a run with SB3 or RLlib, new or resumed, and its report."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any, Sequence

import click
from click.core import ParameterSource

from visualenv.cli.group import (
    shown_option,
    ALGORITHMS,
    difficulty,
    friendly,
    main,
    refuse_code_without_consent,
    trust_code_option,
)
from visualenv.compat.mkl import compatible_mode
from visualenv.errors import ConfigError
from visualenv.train.distill import STUDENT_ENCODERS, DistillConfig
from visualenv.train.run_settings import MAX_TRAIN_SEED


def _parse_value(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


#: the options a resumed run keeps from its config, whatever its backend (either backend adds its own)
FIXED_ON_RESUME = ("frame_stack", "eval_every", "eval_episodes", "final_episodes", "seed", "state_only", "out_root")


@main.command()
@click.argument("spec")
@shown_option("--algo", default="ppo", type=click.Choice(ALGORITHMS))
@click.option(
    "--steps", type=click.IntRange(min=1), default=None, help="total env steps  [default: 200000, or the resumed run's]"
)
@shown_option("--envs", default=2, type=click.IntRange(min=1), help="parallel envs, one Blender process each")
@shown_option("--frame-stack", default=4, type=click.IntRange(min=1), help="frames per observation (1: no stacking)")
@shown_option("--eval-every", default=10000, type=click.IntRange(min=1), help="env steps between evaluations")
@shown_option("--eval-episodes", default=10, type=click.IntRange(min=1))
@shown_option(
    "--final-episodes",
    default=100,
    type=click.IntRange(min=1),
    help="episodes of the best model's final evaluation, on seeds that neither training nor selection uses",
)
@shown_option("--seed", default=0, type=click.IntRange(0, MAX_TRAIN_SEED))
@click.option("--state-only", is_flag=True, help="train on the state vector (MlpPolicy), no rendering")
@click.option(
    "--augment",
    type=click.Choice(["shift"]),
    default=None,
    help="sac, ppo: DrQ's random shift of the frames (pad 4, per sample); sac then trains as DrQ (shared convolutions, "
    "DrQ's update schedule: --set actor_update_interval=N)",
)
@click.option(
    "--set",
    "overrides",
    multiple=True,
    metavar="KEY=VALUE",
    help="algorithm hyperparameter, e.g. --set learning_rate=1e-4; lin_3e-4 decays linearly to 0 over the run",
)
@click.option(
    "--config", "config_file", type=click.Path(exists=True, dir_okay=False), help="YAML file of hyperparameters"
)
@shown_option("-o", "--out", "out_root", default="runs", type=click.Path(file_okay=False))
@click.option(
    "--resume",
    "resume_dir",
    type=click.Path(exists=True, file_okay=False),
    help="continue a run folder of SPEC from its latest checkpoint (--steps, --set and --config may change)",
)
@click.option(
    "--trust-pickle",
    is_flag=True,
    help="with --resume: also resume from a pickle-based checkpoint (an older SB3 run's checkpoints/latest.zip, an "
    "RLlib run's checkpoint folder): unpickling runs whatever code it holds, so only for runs you trust "
    "(docs/security.md)",
)
@click.option("--no-progress", is_flag=True)
@shown_option(
    "--pin/--no-pin",
    default=True,
    help="confine each training env's process (sb3) or EnvRunner (rllib, a free core of its node) to its own cores",
)
@click.option(
    "--batched",
    type=click.IntRange(min=1),
    default=None,
    help="N envs in one Blender scene, one render call per step: sb3: in this process (replaces --envs); "
    "rllib: in each EnvRunner (replaces --envs-per-runner)",
)
@click.option(
    "--workers",
    "batch_workers",
    type=click.IntRange(min=1),
    default=None,
    help="sb3, with --batched N: K processes, each a batch of about N/K envs on its own share of the cores",
)
@click.option(
    "--device",
    "torch_device",
    default=None,
    metavar="auto|cpu|cuda[:N]",
    help="sb3: where the policy acts and learns (SB3's device; default auto: a CUDA GPU if torch sees one)",
)
@click.option(
    "--render-device",
    type=click.Choice(["cpu", "gpu"]),
    default=None,
    help="sb3: where the training envs render (default: the spec's render.device)",
)
@shown_option(
    "--backend",
    default="sb3",
    type=click.Choice(["sb3", "rllib"]),
    help="sb3: Stable-Baselines3 on this machine; rllib: Ray RLlib PPO, on a Ray cluster (the [ray] extra)",
)
@shown_option("--env-runners", default=2, type=click.IntRange(min=1), help="rllib: EnvRunner actors (one Blender each)")
@shown_option("--envs-per-runner", default=1, type=click.IntRange(min=1), help="rllib: envs each runner steps")
@click.option(
    "--address", default=None, help="rllib: the Ray cluster to join (HOST:PORT or 'auto'); default: start a local one"
)
@trust_code_option
@friendly
def train(
    spec: str,
    algo: str,
    steps: int | None,
    envs: int,
    frame_stack: int,
    eval_every: int,
    eval_episodes: int,
    final_episodes: int,
    seed: int,
    state_only: bool,
    overrides: tuple[str, ...],
    config_file: str | None,
    out_root: str,
    resume_dir: str | None,
    trust_pickle: bool,
    no_progress: bool,
    pin: bool,
    batched: int | None,
    backend: str,
    env_runners: int,
    envs_per_runner: int,
    address: str | None,
    batch_workers: int | None = None,
    torch_device: str | None = None,
    render_device: str | None = None,
    trust_code: bool = False,
    augment: str | None = None,
) -> None:
    """Train an agent on SPEC (PPO + CnnPolicy on 4 stacked frames by default).

    Writes runs/<Id>/<timestamp>/: logs (CSV, TensorBoard), best model, plots, results.json.
    With --backend rllib the envs run in Ray RLlib EnvRunners, on this machine or a cluster (--address).
    """
    from visualenv.train.sb3 import TrainConfig, check_config, train as run_training

    ctx = click.get_current_context()
    hyper = _hyperparameters(config_file, overrides)
    if torch_device is not None:
        if "device" in hyper and hyper["device"] != torch_device:
            raise click.BadParameter(
                f"the hyperparameters set device {hyper['device']!r} as well", param_hint="--device"
            )
        hyper["device"] = torch_device
    if trust_pickle and not resume_dir:
        raise click.UsageError("--trust-pickle: only with --resume (a new run unpickles nothing)")
    if _chosen_backend(ctx, backend, resume_dir) == "rllib":
        _train_rllib(ctx, spec, steps, hyper, resume_dir, out_root, address, not no_progress, trust_code)
        return
    if resume_dir:
        _refuse_fixed_on_resume(
            ctx,
            ("algo", "envs", "batched", "batch_workers", "render_device", "augment", *FIXED_ON_RESUME),
            "only --steps, --set and --config change on --resume",
        )
        config = _resumed(TrainConfig, spec, resume_dir, steps, hyper, not no_progress)
    else:
        config = TrainConfig(
            spec=spec,
            algo=algo,
            steps=steps or TrainConfig.steps,
            envs=envs,
            frame_stack=frame_stack,
            eval_every=eval_every,
            eval_episodes=eval_episodes,
            final_eval_episodes=final_episodes,
            seed=seed,
            render=not state_only,
            hyperparams=hyper,
            progress=not no_progress,
            pin=pin,
            render_device=render_device,
            augment=augment,
        )
        if batch_workers is not None and not batched:
            raise click.BadParameter("splits a batch among processes: give --batched N as well", param_hint="--workers")
        if batch_workers is not None and batched is not None and batch_workers > batched:
            raise click.BadParameter(
                f"{batch_workers} workers for a batch of {batched} envs: each worker holds at least one env",
                param_hint="--workers",
            )
        if batched:
            config = dataclasses.replace(config, envs=batched, batched=True, workers=batch_workers)
    check_config(config)  # a misspelt hyperparameter or a too small image fails before a run folder or an env exists
    refuse_code_without_consent(config.spec, trust_code)  # so does a spec's code without consent
    _run(run_training, config, resume_dir, out_root, hyper, trust_code=trust_code, trust_pickle=trust_pickle)


@main.command()
@click.argument("spec")
@click.option(
    "--teacher",
    required=True,
    type=click.Path(exists=True, dir_okay=False),
    help="a state-only policy file of SPEC (best_model.safetensors of `visualenv train SPEC --state-only`)",
)
@click.option(
    "--student",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="start from this policy file of an earlier distillation of SPEC (it acts from the first round on)",
)
@shown_option(
    "--rounds",
    default=DistillConfig.rounds,
    type=click.IntRange(min=1),
    help="DAgger rounds; the teacher acts in the first, the student in the others",
)
@shown_option(
    "--episodes", default=DistillConfig.episodes, type=click.IntRange(min=1), help="episodes rolled out per round"
)
@shown_option(
    "--mixing",
    default=DistillConfig.mixing,
    type=click.FloatRange(0, 1),
    help="the teacher acts a step of round r with probability MIXING ** r, else the student (DAgger's beta)",
)
@shown_option(
    "--epochs",
    default=DistillConfig.epochs,
    type=click.FloatRange(min=0, min_open=True),
    help="passes over all frames gathered so far, per round",
)
@shown_option("--batch-size", default=DistillConfig.batch_size, type=click.IntRange(min=1))
@shown_option("--learning-rate", default=DistillConfig.learning_rate, type=click.FloatRange(min=0, min_open=True))
@shown_option(
    "--shift", default=DistillConfig.shift, type=click.IntRange(min=0), help="random shift of the frames in pixels"
)
@shown_option(
    "--rotate",
    default=DistillConfig.rotate,
    type=click.FloatRange(0, 180),
    help="each training image also turned by up to this many degrees either way (a camera's roll)",
)
@shown_option(
    "--zoom",
    default=DistillConfig.zoom,
    type=click.FloatRange(0, 1, max_open=True),
    help="each training image also scaled by a factor up to this far from 1 (a camera's zoom)",
)
@shown_option("--frame-stack", default=DistillConfig.frame_stack, type=click.IntRange(min=1))
@shown_option(
    "--encoder",
    default=DistillConfig.encoder,
    type=click.Choice(STUDENT_ENCODERS),
    help="the student's image encoder: SB3's NatureCNN, or DrQ's (four 3x3 convolutions: more arithmetic per frame)",
)
@shown_option(
    "--state-loss",
    default=DistillConfig.state_loss,
    type=click.FloatRange(min=0),
    help="weight of an auxiliary loss: the student's CNN features predict the teacher's state (a head not saved)",
)
@shown_option(
    "--consistency",
    default=DistillConfig.consistency,
    type=click.FloatRange(min=0),
    help="weight of a loss pulling the features of each distracted frame toward those of the same state without "
    "distractions (rendered by a twin env; needs --distractions)",
)
@click.option(
    "--distractions",
    default=None,
    callback=lambda ctx, param, value: difficulty(value),
    help="the rounds' frames (rollouts and selection) distracted at this difficulty, 0 to 1, easy, medium, hard, "
    "or LOW:HIGH, drawn per episode, or a distractions section as a YAML mapping ('{difficulty: 0.2, background: "
    "{videos: DIR}}'; docs/distractions.md); the final evaluation stays undistracted",
)
@shown_option(
    "--eval-episodes",
    default=DistillConfig.eval_episodes,
    type=click.IntRange(min=1),
    help="episodes of each round's evaluation, which selects the best round",
)
@shown_option(
    "--final-episodes",
    default=DistillConfig.final_eval_episodes,
    type=click.IntRange(min=1),
    help="episodes of the best round's final evaluation, on seeds neither rounds nor selection use",
)
@shown_option("--seed", default=0, type=click.IntRange(0, MAX_TRAIN_SEED))
@shown_option("-o", "--out", "out_root", default="runs", type=click.Path(file_okay=False))
@click.option("--no-progress", is_flag=True, help="no bar over each round's episodes (the line per round stays)")
@trust_code_option
@friendly
@compatible_mode()  # MKL_CBWR=COMPATIBLE before torch loads: the final evaluation replays in `visualenv eval` on any CPU
def distill(
    spec: str,
    teacher: str,
    student: str | None,
    rounds: int,
    episodes: int,
    mixing: float,
    epochs: float,
    batch_size: int,
    learning_rate: float,
    shift: int,
    rotate: float,
    zoom: float,
    frame_stack: int,
    encoder: str,
    state_loss: float,
    consistency: float,
    distractions: float | list[float] | dict[str, Any] | None,
    eval_episodes: int,
    final_episodes: int,
    seed: int,
    out_root: str,
    no_progress: bool,
    trust_code: bool,
) -> None:
    """Teach a pixel policy (CNN on stacked frames) to act as a state-only TEACHER of SPEC does (DAgger).

    Writes runs/<Id>/<timestamp>/: config.json, rounds.csv, best and final policy files, results.json. docs/distill.md.
    """
    from visualenv.train.distill import distill as run_distill

    config = DistillConfig(
        spec=spec,
        teacher=teacher,
        student=student,
        rounds=rounds,
        episodes=episodes,
        mixing=mixing,
        epochs=epochs,
        batch_size=batch_size,
        learning_rate=learning_rate,
        shift=shift,
        rotate=rotate,
        zoom=zoom,
        frame_stack=frame_stack,
        encoder=encoder,
        state_loss=state_loss,
        consistency=consistency,
        distractions=distractions,
        eval_episodes=eval_episodes,
        final_eval_episodes=final_episodes,
        seed=seed,
        progress=not no_progress,
    )
    _, results = run_distill(config, out_root, log=click.echo, trust_code=trust_code)
    click.echo(
        f"best model over {results['episodes']} episodes: reward {results['mean_reward']:.2f} +- {results['std_reward']:.2f}, "
        f"length {results['mean_length']:.1f}; {results['frames']} frames in {results['wall_time_s']:.0f} s"
    )


def _hyperparameters(config_file: str | None, overrides: tuple[str, ...]) -> dict[str, Any]:
    """--config's mapping, then each --set KEY=VALUE over it."""
    import yaml

    from visualenv.spec.yaml_pitfalls import EXPONENT_NUMBER

    hyper: dict[str, Any] = {}
    if config_file:
        try:
            loaded = yaml.safe_load(Path(config_file).read_text()) or {}
        except yaml.YAMLError as exc:
            raise click.BadParameter(f"{config_file} is not YAML: {exc}", param_hint="--config") from None
        if not isinstance(loaded, dict):
            raise click.BadParameter(
                f"{config_file}: expected a mapping of hyperparameters (name: value), got a {type(loaded).__name__}",
                param_hint="--config",
            )
        # YAML 1.1 reads 3e-4 as text; it is the number --set (JSON) and YAML 1.2 read
        hyper.update(
            {
                key: float(value) if isinstance(value, str) and EXPONENT_NUMBER.match(value) else value
                for key, value in loaded.items()
            }
        )
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep:
            raise click.BadParameter(f"expected KEY=VALUE, got {item!r}", param_hint="--set")
        hyper[key] = _parse_value(value)
    return hyper


def _given(ctx: click.Context, names: Sequence[str]) -> list[str]:
    """The options among `names` given on the command line, as the user spelt them."""
    flags = {"out_root": "--out", "batch_workers": "--workers", "torch_device": "--device"}
    return [
        flags.get(n, f"--{n.replace('_', '-')}")
        for n in names
        if ctx.get_parameter_source(n) is ParameterSource.COMMANDLINE
    ]


def _chosen_backend(ctx: click.Context, backend: str, resume_dir: str | None) -> str:
    """The run's backend (a resumed run keeps its own); options of the other backend are refused."""
    saved_backend = _run_backend(resume_dir) if resume_dir else backend
    if resume_dir and _given(ctx, ["backend"]) and backend != saved_backend:
        raise click.UsageError(
            f"--backend {backend}: {resume_dir} was trained with --backend {saved_backend}; a resumed run keeps its backend"
        )
    if saved_backend == "rllib" or backend == "rllib":
        sb3_only = _given(ctx, ["algo", "envs", "batch_workers", "torch_device", "render_device", "augment"])
        if sb3_only:
            raise click.UsageError(
                f"{', '.join(sb3_only)}: not for --backend rllib (it trains PPO; use --env-runners and --envs-per-runner)"
            )
        return "rllib"
    rllib_only = _given(ctx, ["env_runners", "envs_per_runner", "address"])
    if rllib_only:
        raise click.UsageError(f"{', '.join(rllib_only)}: only with --backend rllib")
    return "sb3"


def _refuse_fixed_on_resume(ctx: click.Context, names: Sequence[str], what_changes: str) -> None:
    fixed = _given(ctx, names)
    if fixed:
        raise click.UsageError(f"{', '.join(fixed)}: a resumed run keeps its settings; {what_changes}")


def _resumed(
    config_class: Any, spec: str, resume_dir: str, steps: int | None, hyper: dict[str, Any], progress: bool
) -> Any:
    """The run's configuration, carried on with SPEC (which training checks is the run's before anything is written)."""
    from visualenv.train.sb3 import resumed_config

    try:
        return resumed_config(
            config_class, Path(resume_dir), steps=steps, hyperparams=hyper, progress=progress, spec=spec
        )
    except ConfigError as exc:
        raise click.BadParameter(str(exc), param_hint="--resume") from None


def _run_backend(run_dir: str) -> str:
    """The backend a run folder was trained with (an older run's as :func:`~visualenv.train.run_folder.migrate`
    reads it)."""
    from visualenv.train.run_folder import read_config

    try:
        return read_config(run_dir)["backend"]
    except ConfigError as exc:
        raise click.BadParameter(str(exc), param_hint="--resume") from None


def _train_rllib(
    ctx: click.Context,
    spec: str,
    steps: int | None,
    hyper: dict[str, Any],
    resume_dir: str | None,
    out_root: str,
    address: str | None,
    progress: bool,
    trust_code: bool = False,
) -> None:
    """`train --backend rllib`: checked before a run folder exists, then visualenv.train.rllib.train."""
    try:
        from visualenv.train.rllib import RLlibTrainConfig, algorithm_config, train as run_training
    except ImportError as exc:
        raise click.UsageError(f"--backend rllib needs Ray RLlib: pip install 'visualenv[ray]' ({exc})") from None
    from visualenv.train.rllib_setup import check_address

    import logging

    # RLlib's notes on its own API changes are not the user's business
    logging.getLogger("ray.rllib").setLevel(logging.ERROR)
    params = ctx.params
    if resume_dir:
        _refuse_fixed_on_resume(
            ctx,
            (*FIXED_ON_RESUME, "env_runners", "envs_per_runner", "batched"),
            "only --steps, --set, --config and --address change on --resume",
        )
        config = _resumed(RLlibTrainConfig, spec, resume_dir, steps, hyper, progress)
    else:
        config = RLlibTrainConfig(
            spec=spec,
            steps=steps or RLlibTrainConfig.steps,
            env_runners=params["env_runners"],
            envs_per_runner=params["envs_per_runner"],
            frame_stack=params["frame_stack"],
            eval_every=params["eval_every"],
            eval_episodes=params["eval_episodes"],
            final_eval_episodes=params["final_episodes"],
            seed=params["seed"],
            render=not params["state_only"],
            hyperparams=hyper,
            progress=progress,
            pin=params["pin"],
        )
        if params["batched"]:
            config = dataclasses.replace(config, envs_per_runner=params["batched"], batched=True)
    check_address(address)
    refuse_code_without_consent(config.spec, trust_code)  # before a Ray cluster starts
    # a misspelt hyperparameter or an observation the encoder cannot take fails before a run folder exists
    algorithm_config(config, trust_code)
    options = {"address": address, "trust_code": trust_code, "trust_pickle": params["trust_pickle"]}
    _run(run_training, config, resume_dir, out_root, hyper, **options)


def _run(
    run_training: Any, config: Any, resume_dir: str | None, out_root: str, hyper: dict[str, Any], **options: Any
) -> None:
    """The run in its folder (the resumed one, or a new one under `out_root`), then its report."""
    from visualenv.env.registration import resolve
    from visualenv.spec.loader import load_spec
    from visualenv.train.evaluation import declares_success
    from visualenv.train.run_folder import new_run_dir

    run_dir = Path(resume_dir) if resume_dir else new_run_dir(out_root, load_spec(resolve(config.spec)).spec.id)
    click.echo(f"run folder: {run_dir}")
    changes = hyper if resume_dir else None
    results = run_training(config, run_dir, resume=bool(resume_dir), changes=changes, **options)
    _report(results, run_dir, declares_success(config.spec))


def _report(results: dict[str, Any], run_dir: Path, succeeds: bool) -> None:
    """The best model's final evaluation in one line (its success rate where the spec declares a success)."""
    click.echo(
        f"best model over {results['episodes']} episodes: reward {results['mean_reward']:.2f} +- {results['std_reward']:.2f}, "
        f"length {results['mean_length']:.1f}"
        + (f", success {100 * results['success_rate']:.0f} %" if succeeds else "")
    )
    from visualenv.train.run_folder import RunFolder

    segment = results.get("segment_wall_time_s")
    since = f" ({segment:.0f} s since the resume)" if segment is not None else ""
    click.echo(
        f"{results['steps']} steps in {results['wall_time_s']:.0f} s{since}; plots in {RunFolder(run_dir).plots}"
    )
