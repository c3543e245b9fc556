"""The `visualenv` command: validate, build, inspect, init, preview, schema, train, play, eval, view, export-policy, bench, info,
compile-kernels.

Bad input never shows a traceback: spec problems print as
``file:line:column: field: message`` lines and exit with status 2.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

import click
from click.core import ParameterSource
import numpy as np

from visualenv.compat.glibc import apply_policy
from visualenv.compat.mkl import compatible_mode
from visualenv.errors import ConfigError, SpecError, VisualEnvError
from visualenv.render.base import READBACKS

#: the SB3 algorithms `train` and `play` take (training.algorithm_class maps them to classes)
ALGORITHMS = ("ppo", "a2c", "dqn", "sac")

EXIT_INVALID = 2
PRETRAINED = "pretrained"  # --model's name for the shipped agent
RANDOM = "random"  # eval --model's name for uniform random actions (the baseline)
MODEL_HELP = ("a policy file (policy.safetensors with its policy.json, as export-policy and train write) or 'pretrained' (the shipped "
              "agent, results/<Id>/policy.safetensors){}; a .zip, .pt or RLlib checkpoint folder only with --trust-pickle")
trust_pickle_option = click.option(
    "--trust-pickle", is_flag=True,
    help="also load pickle-based models (SB3 .zip, torch .pt/.pth, RLlib checkpoint folders): unpickling runs whatever code the file "
         "holds, so only for files you trust (docs/security.md)")


def _friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn visualenv's own errors into messages and exit codes."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except SpecError as exc:
            for diagnostic in exc.diagnostics:
                click.echo(str(diagnostic), err=True)
            for note in exc.notes:
                click.echo(note, err=True)
            sys.exit(EXIT_INVALID)
        except VisualEnvError as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(1)
        except KeyboardInterrupt:
            click.echo("interrupted", err=True)
            sys.exit(130)

    return wrapper


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="visualenv")
def main() -> None:
    """Compile declarative specs into Gymnasium environments rendered by Blender."""
    apply_policy()  # a process visualenv owns: freed memory kept for the next render call (visualenv.compat.glibc)


@main.command()
@click.argument("specs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@_friendly
def validate(specs: tuple[str, ...]) -> None:
    """Check spec files (format, names, expressions); prints "ok" for each valid file."""
    from visualenv.compiler.program import compile_spec
    from visualenv.spec.loader import load_spec

    problems: list[Any] = []
    for path in specs:
        try:
            compile_spec(load_spec(path))
        except SpecError as exc:
            problems.extend(exc.diagnostics)
            continue
        click.echo("ok" if len(specs) == 1 else f"{path}: ok")
    if problems:
        raise SpecError(problems)


@main.command()
@_friendly
def schema() -> None:
    """Print the JSON Schema of the spec format (for editors)."""
    from visualenv.spec.schema import spec_json_schema

    click.echo(json.dumps(spec_json_schema(), indent=2))


@main.command()
@click.argument("spec", type=click.Path(dir_okay=False))
@click.option("-o", "--out", "out_dir", default="build", show_default=True, type=click.Path(file_okay=False), help="parent folder of the build")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0), help="seed of the previewed reset")
@click.option("--device", type=click.Choice(["cpu", "gpu", "auto"]), default=None, help="override render.device")
@click.option("--quiet", is_flag=True, help="do not print the observation preview")
@_friendly
def build(spec: str, out_dir: str, seed: int, device: str | None, quiet: bool) -> None:
    """Validate and compile SPEC, build its Blender scene, render a preview.

    Writes build/<Id>/env.json (resolved spec, versions, hash), scene.blend
    (opens in Blender) and preview.png (observation beside the high-res view).
    An earlier build is replaced only when the new one succeeded.
    """
    from visualenv.tools.build import build_env

    result = build_env(spec, out_dir, seed=seed, device=device)
    click.echo(f"built {result.env_id} in {result.seconds:.1f} s -> {result.folder}/")
    for line in result.summary:
        click.echo("  " + line)
    if not quiet and result.ascii_preview:
        click.echo(f"observation (reset, seed {seed}{'; ' + result.ascii_note if result.ascii_note else ''}):")
        click.echo(result.ascii_preview)


@main.command()
@click.argument("blend", type=click.Path(exists=True, dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="print the report as JSON (for tools)")
@_friendly
def inspect(blend: str, as_json: bool) -> None:
    """What BLEND holds for a spec: scenes, cameras, lights, meshes, materials, animation, and what the spec overrides.

    Given an MJCF model (.xml), the names its expressions can read: joints, bodies, sites, sensors, actuators, geoms.

    The file is read in a child process: a file that crashes Blender is reported, not fatal.
    """
    from visualenv.render.blender import blendfile
    from visualenv.tools.mjcf_starter import is_mjcf, mjcf_report
    from visualenv.tools.starter import format_report

    if is_mjcf(Path(blend)):  # an MJCF model: the names expressions can read (docs/physics.md)
        click.echo(mjcf_report(Path(blend)))
        return
    info = blendfile.describe(_blend_path(blend))
    click.echo(json.dumps(info, indent=1, ensure_ascii=False) if as_json else format_report(info))


@main.command()
@click.argument("blend", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--out", "out_path", default=None, type=click.Path(dir_okay=False), help="spec file to write [default: <blend name>.yaml here]")
@click.option("--force", is_flag=True, help="replace an existing spec file")
@_friendly
def init(blend: str, out_path: str | None, force: bool) -> None:
    """Write a starter spec over BLEND that builds as it is: the file's scene, its first camera, placeholder state, actions and dynamics.

    Given an MJCF model (.xml): MuJoCo physics, actions from its actuators, a camera that frames it, its names as comments.
    """
    from visualenv.render.blender import blendfile
    from visualenv.tools.mjcf_starter import is_mjcf, mjcf_starter_spec
    from visualenv.tools.starter import starter_spec

    mjcf = is_mjcf(Path(blend))
    path = Path(blend) if mjcf else _blend_path(blend)
    out = Path(out_path) if out_path else Path(path.stem + ".yaml")
    if out.exists() and not force:
        raise VisualEnvError(f"{out} exists: choose another name with -o, or replace it with --force")
    text = mjcf_starter_spec(path, out) if mjcf else starter_spec(blendfile.describe(path), path, out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise VisualEnvError(f"cannot write {out}: {exc.strerror}") from None
    click.echo(f"wrote {out}: edit the placeholders, then `visualenv build {out}`")


def _blend_path(blend: str) -> Path:
    from visualenv.render.blender.blendfile import is_blend_file

    path = Path(blend)
    if not is_blend_file(path):
        raise VisualEnvError(f"not a Blender file: {path} (a .blend saved by Blender is needed)")
    return path


@main.command()
@click.argument("spec", type=click.Path())
@click.option("-o", "--out", "out_dir", default="frames", show_default=True, type=click.Path(file_okay=False))
@click.option("--steps", default=20, show_default=True, type=click.IntRange(min=1), help="steps of the random episode")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0))
@_friendly
def preview(spec: str, out_dir: str, steps: int, seed: int) -> None:
    """Save a few frames (observation beside the high-res view) of a random episode."""
    from visualenv.tools.build import preview_frames

    paths = preview_frames(spec, out_dir, steps=steps, seed=seed, progress=True)
    click.echo(f"wrote {len(paths)} frames to {out_dir}/")


def _video_path(value: str | None) -> str | None:
    """--record checked as play() checks it, reported as a bad option."""
    from visualenv.train.play import check_recording

    if value is not None:
        try:
            check_recording(value)
        except VisualEnvError as exc:
            raise click.BadParameter(str(exc), param_hint="--record") from None
    return value


def _model_file(spec: str, value: str) -> str:
    """--model: a model file or checkpoint folder, or 'pretrained' for the shipped agent of the spec's env (results/<Id>/policy.safetensors)."""
    if value == PRETRAINED:
        from visualenv.train.models import pretrained_model
        from visualenv.env.registration import resolve
        from visualenv.spec.loader import load_spec

        return str(pretrained_model(load_spec(resolve(spec)).spec.id))
    if not Path(value).exists():  # a file, or an RLlib checkpoint folder: load_model tells which it is not
        raise click.BadParameter(f"{value}: no such file (or '{PRETRAINED}' for the shipped agent)", param_hint="--model")
    return value


def _parse_value(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


@main.command()
@click.argument("spec")
@click.option("--algo", type=click.Choice(ALGORITHMS), default="ppo", show_default=True)
@click.option("--steps", type=click.IntRange(min=1), default=None, help="total env steps  [default: 200000, or the resumed run's]")
@click.option("--envs", default=2, show_default=True, type=click.IntRange(min=1), help="parallel envs, one Blender process each")
@click.option("--frame-stack", default=4, show_default=True, type=click.IntRange(min=1), help="frames per observation (1: no stacking)")
@click.option("--eval-every", default=10_000, show_default=True, type=click.IntRange(min=1), help="env steps between evaluations")
@click.option("--eval-episodes", default=10, show_default=True, type=click.IntRange(min=1))
@click.option("--final-episodes", default=100, show_default=True, type=click.IntRange(min=1),
              help="episodes of the best model's final evaluation, on seeds that neither training nor selection uses")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(0, 2**31 - 1))
@click.option("--state-only", is_flag=True, help="train on the state vector (MlpPolicy), no rendering")
@click.option("--set", "overrides", multiple=True, metavar="KEY=VALUE", help="algorithm hyperparameter, e.g. --set learning_rate=1e-4; lin_3e-4 decays linearly to 0 over the run")
@click.option("--config", "config_file", type=click.Path(exists=True, dir_okay=False), help="YAML file of hyperparameters")
@click.option("-o", "--out", "out_root", default="runs", show_default=True, type=click.Path(file_okay=False))
@click.option("--resume", "resume_dir", type=click.Path(exists=True, file_okay=False), help="continue a run folder from its latest checkpoint (--steps, --set and --config may change)")
@click.option("--no-progress", is_flag=True)
@click.option("--pin/--no-pin", default=True, show_default=True,
              help="confine each training env's process (sb3) or EnvRunner (rllib, a free core of its node) to its own cores")
@click.option("--batched", type=click.IntRange(min=1), default=None,
              help="N envs in one Blender scene, one render call per step: sb3: in this process (replaces --envs); "
                   "rllib: in each EnvRunner (replaces --envs-per-runner)")
@click.option("--workers", "batch_workers", type=click.IntRange(min=1), default=None,
              help="sb3, with --batched N: K processes, each a batch of about N/K envs on its own share of the cores")
@click.option("--backend", type=click.Choice(["sb3", "rllib"]), default="sb3", show_default=True,
              help="sb3: Stable-Baselines3 on this machine; rllib: Ray RLlib PPO, on a Ray cluster (the [ray] extra)")
@click.option("--env-runners", default=2, show_default=True, type=click.IntRange(min=1), help="rllib: EnvRunner actors (one Blender each)")
@click.option("--envs-per-runner", default=1, show_default=True, type=click.IntRange(min=1), help="rllib: envs each runner steps")
@click.option("--address", default=None, help="rllib: the Ray cluster to join (HOST:PORT or 'auto'); default: start a local one")
@_friendly
def train(spec: str, algo: str, steps: int | None, envs: int, frame_stack: int, eval_every: int, eval_episodes: int,
          final_episodes: int, seed: int, state_only: bool, overrides: tuple[str, ...], config_file: str | None,
          out_root: str, resume_dir: str | None, no_progress: bool, pin: bool, batched: int | None, backend: str, env_runners: int,
          envs_per_runner: int, address: str | None, batch_workers: int | None = None) -> None:
    """Train an agent on SPEC (PPO + CnnPolicy on 4 stacked frames by default).

    Writes runs/<Id>/<timestamp>/: logs (CSV, TensorBoard), best model, plots, results.json.
    With --backend rllib the envs run in Ray RLlib EnvRunners, on this machine or a cluster (--address).
    """
    from visualenv.env.registration import resolve
    from visualenv.spec.loader import load_spec
    from visualenv.train.sb3 import TrainConfig, check_config, new_run_dir, train as run_training

    ctx = click.get_current_context()
    hyper = _hyperparameters(config_file, overrides)
    if _chosen_backend(ctx, backend, resume_dir) == "rllib":
        _train_rllib(ctx, spec, steps, hyper, resume_dir, out_root, address, not no_progress)
        return
    if resume_dir:
        _refuse_fixed_on_resume(ctx, ("algo", "envs", "batched", "batch_workers", "frame_stack", "eval_every", "eval_episodes", "final_episodes", "seed", "state_only",
                                      "out_root"),
                                "only --steps, --set and --config change on --resume")
        config = _resumed(TrainConfig, resume_dir, steps, hyper, not no_progress)
    else:
        config = TrainConfig(spec=spec, algo=algo, steps=steps or TrainConfig.steps, envs=envs, frame_stack=frame_stack, eval_every=eval_every,
                             eval_episodes=eval_episodes, final_eval_episodes=final_episodes, seed=seed,
                             render=not state_only, hyperparams=hyper, progress=not no_progress, pin=pin)
        if batch_workers is not None and not batched:
            raise click.BadParameter("splits a batch among processes: give --batched N as well", param_hint="--workers")
        if batch_workers is not None and batched is not None and batch_workers > batched:
            raise click.BadParameter(f"{batch_workers} workers for a batch of {batched} envs: each worker holds at least one env",
                                     param_hint="--workers")
        if batched:
            config = dataclasses.replace(config, envs=batched, batched=True, workers=batch_workers)
    check_config(config)  # a misspelt hyperparameter or a too small image fails before a run folder or an env exists
    run_dir = Path(resume_dir) if resume_dir else new_run_dir(out_root, load_spec(resolve(spec)).spec.id)
    click.echo(f"run folder: {run_dir}")
    results = run_training(config, run_dir, resume=bool(resume_dir), changes=hyper if resume_dir else None)
    _report(results, run_dir)


def _hyperparameters(config_file: str | None, overrides: tuple[str, ...]) -> dict[str, Any]:
    """--config's mapping, then each --set KEY=VALUE over it."""
    import yaml

    hyper: dict[str, Any] = {}
    if config_file:
        try:
            loaded = yaml.safe_load(Path(config_file).read_text()) or {}
        except yaml.YAMLError as exc:
            raise click.BadParameter(f"{config_file} is not YAML: {exc}", param_hint="--config") from None
        if not isinstance(loaded, dict):
            raise click.BadParameter(f"{config_file}: expected a mapping of hyperparameters (name: value), got a {type(loaded).__name__}", param_hint="--config")
        hyper.update(loaded)
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep:
            raise click.BadParameter(f"expected KEY=VALUE, got {item!r}", param_hint="--set")
        hyper[key] = _parse_value(value)
    return hyper


def _given(ctx: click.Context, names: Sequence[str]) -> list[str]:
    """The options among `names` given on the command line, as the user spelt them."""
    flags = {"out_root": "--out", "batch_workers": "--workers"}
    return [flags.get(n, f"--{n.replace('_', '-')}") for n in names if ctx.get_parameter_source(n) is ParameterSource.COMMANDLINE]


def _chosen_backend(ctx: click.Context, backend: str, resume_dir: str | None) -> str:
    """The run's backend (a resumed run keeps its own); options of the other backend are refused."""
    saved_backend = _run_backend(resume_dir) if resume_dir else backend
    if resume_dir and _given(ctx, ["backend"]) and backend != saved_backend:
        raise click.UsageError(f"--backend {backend}: {resume_dir} was trained with --backend {saved_backend}; a resumed run keeps its backend")
    if saved_backend == "rllib" or backend == "rllib":
        sb3_only = _given(ctx, ["algo", "envs", "batch_workers"])
        if sb3_only:
            raise click.UsageError(f"{', '.join(sb3_only)}: not for --backend rllib (it trains PPO; use --env-runners and --envs-per-runner)")
        return "rllib"
    rllib_only = _given(ctx, ["env_runners", "envs_per_runner", "address"])
    if rllib_only:
        raise click.UsageError(f"{', '.join(rllib_only)}: only with --backend rllib")
    return "sb3"


def _refuse_fixed_on_resume(ctx: click.Context, names: Sequence[str], what_changes: str) -> None:
    fixed = _given(ctx, names)
    if fixed:
        raise click.UsageError(f"{', '.join(fixed)}: a resumed run keeps its settings; {what_changes}")


def _resumed(config_class: Any, resume_dir: str, steps: int | None, hyper: dict[str, Any], progress: bool) -> Any:
    from visualenv.train.sb3 import resumed_config

    try:
        return resumed_config(config_class, Path(resume_dir), steps=steps, hyperparams=hyper, progress=progress)
    except ConfigError as exc:
        raise click.BadParameter(str(exc), param_hint="--resume") from None


def _run_backend(run_dir: str) -> str:
    """The backend a run folder was trained with (config.json's 'backend'; SB3 runs predate the key)."""
    try:
        return json.loads((Path(run_dir) / "config.json").read_text()).get("backend", "sb3")
    except (OSError, ValueError, AttributeError):
        return "sb3"  # the SB3 path reports the broken folder


def _train_rllib(ctx: click.Context, spec: str, steps: int | None, hyper: dict[str, Any], resume_dir: str | None, out_root: str,
                 address: str | None, progress: bool) -> None:
    """`train --backend rllib`: checked before a run folder exists, then visualenv.train.rllib.train."""
    try:
        from visualenv.train.rllib import RLlibTrainConfig, algorithm_config, train as run_training
    except ImportError as exc:
        raise click.UsageError(f"--backend rllib needs Ray RLlib: pip install 'visualenv[ray]' ({exc})") from None
    from visualenv.env.registration import resolve
    from visualenv.train.rllib_setup import check_address
    from visualenv.spec.loader import load_spec
    from visualenv.train.sb3 import new_run_dir

    import logging

    logging.getLogger("ray.rllib").setLevel(logging.ERROR)  # RLlib's notes on its own API changes are not the user's business
    params = ctx.params
    if resume_dir:
        _refuse_fixed_on_resume(ctx, ("frame_stack", "eval_every", "eval_episodes", "final_episodes", "seed", "state_only", "out_root", "env_runners",
                                      "envs_per_runner", "batched"), "only --steps, --set, --config and --address change on --resume")
        config = _resumed(RLlibTrainConfig, resume_dir, steps, hyper, progress)
    else:
        config = RLlibTrainConfig(spec=spec, steps=steps or RLlibTrainConfig.steps, env_runners=params["env_runners"],
                                  envs_per_runner=params["envs_per_runner"], frame_stack=params["frame_stack"], eval_every=params["eval_every"],
                                  eval_episodes=params["eval_episodes"], final_eval_episodes=params["final_episodes"], seed=params["seed"],
                                  render=not params["state_only"], hyperparams=hyper, progress=progress, pin=params["pin"])
        if params["batched"]:
            config = dataclasses.replace(config, envs_per_runner=params["batched"], batched=True)
    check_address(address)
    algorithm_config(config)  # a misspelt hyperparameter or an observation the encoder cannot take fails before a run folder exists
    run_dir = Path(resume_dir) if resume_dir else new_run_dir(out_root, load_spec(resolve(config.spec)).spec.id)
    click.echo(f"run folder: {run_dir}")
    results = run_training(config, run_dir, resume=bool(resume_dir), changes=hyper if resume_dir else None, address=address)
    _report(results, run_dir)


def _report(results: dict[str, Any], run_dir: Path) -> None:
    click.echo(f"best model over {results['episodes']} episodes: reward {results['mean_reward']:.2f} +- {results['std_reward']:.2f}, "
               f"length {results['mean_length']:.1f}, success {100 * results['success_rate']:.0f} %")
    click.echo(f"{results['steps']} steps in {results['wall_time_s']:.0f} s; plots in {run_dir / 'plots'}")


@main.command()
@click.argument("spec")
@click.option("--model", "model_path", help=MODEL_HELP.format("") + "  [default: random actions]")
@trust_pickle_option
@click.option("--algo", type=click.Choice(ALGORITHMS), default="ppo", show_default=True)
@click.option("--episodes", default=3, show_default=True, type=click.IntRange(min=1))
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0))
@click.option("--record", type=click.Path(dir_okay=False), callback=lambda ctx, param, value: _video_path(value),
              help="save a .gif, .webp (smallest) or .mp4 of the view beside the observation")
@click.option("--view", "view_preset", type=click.Choice(["fast", "quality"]), default=None,
              help="render preset of the recorded view (default: the spec's; 'fast' records in seconds)")
@click.option("--view-size", type=click.IntRange(16, 4096), default=None, help="longer side of the recorded view in pixels")
@_friendly
@compatible_mode()  # MKL_CBWR=COMPATIBLE before torch loads: the policy's products alike on every CPU
def play(spec: str, model_path: str | None, trust_pickle: bool, algo: str, episodes: int, seed: int, record: str | None,
         view_preset: str | None, view_size: int | None) -> None:
    """Run episodes with a random or trained policy; print returns, lengths and success."""
    from visualenv.train.play import play as run_play

    if model_path is not None:
        model_path = _model_file(spec, model_path)
    results = run_play(spec, model_path=model_path, algo=algo, episodes=episodes, seed=seed, record=record,
                       view_preset=view_preset, view_size=view_size, trust_pickle=trust_pickle)
    for i, ep in enumerate(results):
        click.echo(f"episode {i}: return {ep.ret:.2f}, length {ep.length}, {'success' if ep.success else 'no success'} ({ep.outcome})")
    rate = sum(ep.success for ep in results) / len(results)
    click.echo(f"mean return {np.mean([ep.ret for ep in results]):.2f}, mean length {np.mean([ep.length for ep in results]):.1f}, success {100 * rate:.0f} %")
    if record:
        click.echo(f"recorded {record}")


@main.command("eval")
@click.argument("spec")
@click.option("--model", "model_path", required=True, help=MODEL_HELP.format(", or 'random' (uniform random actions, the baseline)"))
@trust_pickle_option
@click.option("--algo", type=click.Choice(ALGORITHMS), default=None, help="the model's algorithm  [default: its run's (config.json), else ppo]")
@click.option("--episodes", type=click.IntRange(min=1), default=None, help="deterministic episodes  [default: its run's final evaluation's, else 100]")
@click.option("--seed", type=click.IntRange(min=0), default=None,
              help="seed of the evaluation env  [default: its run's final evaluation's (results.json's eval_seed), else 12884901888, a seed no run trains, selects or reports on]")
@click.option("-o", "--out", "json_out", type=click.Path(dir_okay=False), help="also write the figures as JSON")
@click.option("--write-results", is_flag=True,
              help="record this evaluation as the results.json beside the model (its run's other keys kept): how a shipped file's figures are made")
@_friendly
@compatible_mode()  # MKL_CBWR=COMPATIBLE before torch loads: the policy's products alike on every CPU
def eval_command(spec: str, model_path: str, trust_pickle: bool, algo: str | None, episodes: int | None, seed: int | None,
                 json_out: str | None, write_results: bool) -> None:
    """Evaluate a trained model (or random actions) on SPEC: mean return, mean length and success rate of deterministic episodes, with 95 % intervals.

    The intervals are a percentile bootstrap of the mean (return, length) and Wilson's
    (success rate). With the seed of the model's run (the default when its results.json
    and config.json lie beside the model, as in runs/<Id>/<time>/ and results/<Id>/),
    the episodes are those of the run's final evaluation and the figures match its results.json:
    bit for bit on a machine like the one that wrote it, else within a stated tolerance (docs/testing.md).
    """
    from visualenv.train.evaluation import (TOLERANCE_TEXT, differences, evaluate_model, evaluate_random, replays_prefix, sample_differences,
                                             seed_purpose)
    from visualenv.train.reproducible import unlike

    if json_out:
        _check_writable(json_out, "--out")
    if model_path == RANDOM:
        results, recorded = evaluate_random(spec, episodes=episodes, seed=seed), None
        click.echo(f"uniform random actions (the baseline): {results['episodes']} episodes, the first reset with seed {results['eval_seed']}")
    else:
        model_path = _model_file(spec, model_path)
        results, recorded = evaluate_model(spec, model_path, algo=algo, episodes=episodes, seed=seed, trust_pickle=trust_pickle)
        click.echo(f"{model_path}: {results['episodes']} deterministic episodes, the first reset with seed {results['eval_seed']}")
    purpose = seed_purpose(results["eval_seed"])
    if purpose in ("training", "selection"):
        click.echo(f"note: seed {results['eval_seed']} lies in the {purpose} band: a run seeded near it has seen these episodes "
                   "(the defaults play episodes no run trains or selects on)")
    (r_lo, r_hi), (l_lo, l_hi), (s_lo, s_hi) = results["reward_ci95"], results["length_ci95"], results["success_ci95"]
    click.echo(f"  mean return   {results['mean_reward']:8.2f}  95 % CI [{r_lo:.2f}, {r_hi:.2f}] (bootstrap), std {results['std_reward']:.2f}")
    click.echo(f"  mean length   {results['mean_length']:8.2f}  95 % CI [{l_lo:.2f}, {l_hi:.2f}] (bootstrap)")
    click.echo(f"  success rate  {100 * results['success_rate']:6.0f} %  95 % CI [{100 * s_lo:.0f} %, {100 * s_hi:.0f} %] (Wilson)")
    matches, comparison, sample = None, None, None
    if recorded is not None and recorded.results is not None and (
            recorded.results.get("episodes") == results["episodes"] or replays_prefix(results, recorded.results)):
        other_machine = unlike(recorded.results.get("machine"), results["machine"])
        comparison = "tolerance" if other_machine else "exact"
        if other_machine:
            click.echo(f"note: this machine is unlike the one that wrote results.json ({'; '.join(other_machine)}): "
                       f"episodes are compared within a tolerance ({TOLERANCE_TEXT}), not bit for bit")
        wrong = differences(results, recorded.results, tolerant=bool(other_machine))
        matches = not wrong
        what = "its run's results.json" if recorded.results["episodes"] == results["episodes"] else \
            f"the first {results['episodes']} episodes of its run's results.json"
        click.echo((f"reproduces {what}" + (" within that tolerance" if other_machine else "")) if matches
                   else f"differs from {what}: " + "; ".join(wrong[:5]))
        if not matches and other_machine:  # a chaotic episode grows last-digit differences: the episodes are a new sample
            sample = sample_differences(results, recorded.results)
            click.echo("as a sample of results.json's episodes (a long chaotic episode does not replay on other kernels): "
                       + ("consistent" if not sample else "not consistent: " + "; ".join(sample))
                       + " (docs/testing.md, 'Deterministic rendering')")
        if recorded.note:
            click.echo(f"note: {recorded.note}")
    if write_results:
        click.echo(f"wrote {_write_results(results, model_path, spec)}")
    if json_out:
        record = {"spec": spec, "model": model_path, **results, "matches_results_json": matches, "comparison": comparison,
                  "consistent_sample": None if sample is None else not sample}
        Path(json_out).write_text(json.dumps(record, indent=2) + "\n")
        click.echo(f"wrote {json_out}")


def _write_results(results: dict, model_path: str, spec: str) -> Path:
    """`eval --write-results`: the evaluation becomes results.json beside the model; what the run recorded besides the
    figures (selection, steps, wall time) is kept, and `evaluated` says which file and command made them."""
    if model_path == RANDOM:
        raise click.BadParameter("random actions have no results.json of their own", param_hint="--write-results")
    path = Path(model_path).parent / "results.json"
    kept = json.loads(path.read_text()) if path.is_file() else {}
    kept.pop("reevaluated", None)
    command = f"visualenv eval {spec} --model {model_path} --seed {results['eval_seed']} --episodes {results['episodes']}"
    path.write_text(json.dumps({**kept, **results, "evaluated": {"file": Path(model_path).name, "command": command}}, indent=2) + "\n")
    return path


@main.command()
@click.argument("spec")
@click.option("--model", "model_path", help="an agent plays: a trained model (as `play` takes), or 'pretrained': the shipped agent; default: you play with the keys")
@click.option("--algo", type=click.Choice(ALGORITHMS), default="ppo", show_default=True)
@click.option("--port", type=click.IntRange(0, 65535), default=None, help="[default: 8765, or any free port where it is taken; 0: any free port]")
@click.option("--host", default="127.0.0.1", show_default=True, help="the address to serve on (another than this machine's own: a warning)")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0), help="seed of the first episode (the next ones count up)")
@click.option("--view", "view_preset", type=click.Choice(["fast", "quality", "off"]), default="fast", show_default=True, help="the high-resolution view's preset")
@click.option("--view-size", type=click.IntRange(16, 4096), default=320, show_default=True, help="longer side of the view in pixels")
@trust_pickle_option
@_friendly
def view(spec: str, model_path: str | None, algo: str, port: int | None, host: str, seed: int, view_preset: str, view_size: int,
         trust_pickle: bool) -> None:
    """Show SPEC live on a local web page: play it with the keys or watch an agent; saving the spec rebuilds it (docs/viewer.md)."""
    from visualenv.viewer.app import serve
    from visualenv.viewer.session import ViewOptions

    serve(spec, model=model_path, algo=algo, host=host, port=port, seed=seed, view=ViewOptions(None if view_preset == "off" else view_preset, view_size),
          echo=lambda line: click.echo(line, err=line.startswith("warning")), trust_pickle=trust_pickle)


@main.command("export-policy")
@click.argument("model", type=click.Path(exists=True))
@click.argument("out", type=click.Path(dir_okay=False))
@trust_pickle_option
@click.option("--algo", type=click.Choice(ALGORITHMS), default="ppo", show_default=True, help="the algorithm of an SB3 .zip")
@click.option("--float32", "full", is_flag=True, help="keep float32 weights (default: float16, half the size)")
@_friendly
def export_policy(model: str, out: str, trust_pickle: bool, algo: str, full: bool) -> None:
    """Write the policy of a trained model as a policy file: OUT.safetensors (its weights) and OUT.json (what builds the
    network), without the optimizer's state; what the shipped agents in results/ are.

    MODEL: an SB3 .zip, a torch .pt or an RLlib checkpoint folder (with --trust-pickle: loading them runs whatever code
    they hold), or a policy file. `play`, `eval` and `--model` then load OUT without unpickling anything (docs/security.md).
    """
    from visualenv.train.models import export_policy as write
    from visualenv.train.policy_format import WEIGHTS

    if Path(out).suffix != WEIGHTS:
        raise click.BadParameter(f"expected a file ending in {WEIGHTS} (its .json is written beside it)", param_hint="OUT")
    path = write(model, out, algo=algo, half=not full, trust_pickle=trust_pickle)
    click.echo(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB, {'float32' if full else 'float16'} weights) and {path.with_suffix('.json').name}")


def _check_writable(path: str, option: str) -> None:
    """A figure file that cannot be written is refused now, not after minutes of measuring (its folder is made)."""
    from visualenv.files import make_dir

    try:
        make_dir(Path(path).parent)
        Path(path).touch()
    except (OSError, VisualEnvError) as exc:
        raise click.BadParameter(f"cannot write {path}: {getattr(exc, 'strerror', None) or exc}", param_hint=option) from None


def _worker_counts(value: str, option: str = "--workers") -> tuple[int, ...]:
    """--workers: one count, or a comma-separated list of counts (scaling); --batched: a list of batch sizes."""
    try:
        counts = tuple(int(part) for part in value.split(","))
    except ValueError:
        counts = ()
    least = 1 if option == "--batched" else 0
    if not counts or any(c < least for c in counts) or (len(counts) > 1 and min(counts) < 1):
        what = "batch sizes" if option == "--batched" else "a number of workers"
        raise click.BadParameter(f"expected {what} or a list such as 1,2,4,8, got {value!r}", param_hint=option)
    return counts


def _bench_batched(specs: tuple[str, ...], sizes: tuple[int, ...], steps: int, cores: int, autoreset: str, results: list[Any],
                   split: tuple[int, ...] | None = None, device: str | None = None) -> None:
    """`bench --batched`: each batch size in a fresh process (or in K workers each, `split`), then the per-process
    vector env with one worker per usable core."""
    from visualenv.tools.bench import bench_parallel
    from visualenv.tools.bench_batched import bench_batched, lines

    for k in split or ():
        if not 1 <= k <= min(sizes):
            raise click.BadParameter(f"with --batched, each count of workers must be from 1 to the smallest batch size ({min(sizes)}): "
                                     f"each worker holds a batch of at least one env, got {k}", param_hint="--workers")
    for spec in specs:
        batches = bench_batched(spec, sizes, steps, autoreset=autoreset, workers=split or (None,), device=device)
        workers = max(2, cores)
        per_process = bench_parallel(spec, workers, steps, 0, 0.0, device=device)
        click.echo(f"{spec}")
        for line in lines(batches, per_process):
            click.echo(line)
        results.append({"spec": spec, "batched": batches, "per_process": per_process})


@main.command()
@click.argument("specs", nargs=-1, required=True)
@click.option("--steps", default=500, show_default=True, type=click.IntRange(min=1), help="measured env steps (after a warm-up)")
@click.option("--workers", default="2", show_default=True, callback=lambda ctx, param, value: _worker_counts(value),
              help="parallel envs for the parallel figure (0: skip); a list such as 1,2,4,8 measures scaling against one confined worker; "
                   "with --batched: K worker processes sharing each batch size (a list such as 1,2 measures each)")
@click.option("--threads", type=click.IntRange(min=1), default=None, help="render threads of the single env (default: all cores)")
@click.option("--readback", type=click.Choice(READBACKS), default="auto", show_default=True,
              help="how pixels leave Blender (file: the BMP path, for before/after comparisons)")
@click.option("--pin/--no-pin", default=True, show_default=True, help="confine each parallel worker to its own cores")
@click.option("--soak", "soak_steps", type=click.IntRange(min=0), default=0, help="also run this many steps and report memory growth (e.g. 50000)")
@click.option("--batched", "batch_sizes", default=None, callback=lambda ctx, param, value: value and _worker_counts(value, "--batched"),
              help="batch sizes such as 1,16,64: N envs in one Blender against the per-process vector env (one worker per core)")
@click.option("--autoreset", type=click.Choice(["next_step", "same_step"]), default="next_step", show_default=True,
              help="with --batched: when an ended env is reset (same_step: as SB3's VecEnvs and train --batched do)")
@click.option("--device", type=click.Choice(["cpu", "gpu"]), default=None, help="render on this device (default: the spec's render.device)")
@click.option("--json", "json_out", type=click.Path(dir_okay=False), help="also write the figures as JSON")
@_friendly
def bench(specs: tuple[str, ...], steps: int, workers: tuple[int, ...], threads: int | None, readback: str, pin: bool, soak_steps: int,
          batch_sizes: tuple[int, ...] | None, autoreset: str, device: str | None, json_out: str | None) -> None:
    """Measure steps/s, render time, overhead vs the raw render floor, memory, parallel speed-up."""
    import platform

    import psutil

    from visualenv.tools.bench import as_dict, bench_one
    from visualenv.env.cores import usable_cores

    if json_out:
        _check_writable(json_out, "--json")
    cores = len(usable_cores())
    machine_cores = psutil.cpu_count() or cores
    click.echo(f"machine: {platform.processor() or platform.machine()}, {machine_cores} cores"
               f"{f' ({cores} usable by this process)' if cores != machine_cores else ''}, "
               f"{psutil.virtual_memory().total / 2**30:.0f} GiB, Python {platform.python_version()}")
    results: list[Any] = []
    if batch_sizes:
        split = workers if click.get_current_context().get_parameter_source("workers") is ParameterSource.COMMANDLINE else None
        _bench_batched(specs, batch_sizes, steps, cores, autoreset, results, split, device)
    for spec in specs if not batch_sizes else ():
        single, scaling = (workers[0], ()) if len(workers) == 1 else (0, workers)
        figures = bench_one(spec, steps, workers=single, soak_steps=soak_steps, threads=threads, readback=readback, pin=pin, scaling=scaling,
                            device=device)
        for line in figures.lines():
            click.echo(line)
        results.append(as_dict(figures))
    if json_out:
        Path(json_out).write_text(json.dumps(results, indent=2) + "\n")


@main.command()
@click.option("--json", "as_json", is_flag=True, help="print the report as JSON")
@click.option("--warm-gpu", is_flag=True, help="render one Cycles GPU frame now, so the driver compiles and caches the kernels before training")
@_friendly
def info(as_json: bool, warm_gpu: bool) -> None:
    """Versions, usable cores, and what Blender can render on here: Cycles devices per backend, EEVEE/Workbench's context, kernel caches."""
    from visualenv.tools.info import format_report, gather

    report = gather(warm_gpu=warm_gpu)
    click.echo(json.dumps(report, indent=2) if as_json else format_report(report))


@main.command("compile-kernels")
@click.option("--arch", "archs", multiple=True, help="CUDA architecture such as sm_90 (repeatable; default: this machine's NVIDIA GPUs)")
@click.option("--ptxas", type=click.Path(dir_okay=False), default=None, help="the CUDA toolkit's ptxas (default: PATH, $CUDA_HOME, /usr/local/cuda)")
@click.option("--force", is_flag=True, help="compile again where the kernel cache already holds the architecture's binary")
@_friendly
def compile_kernels(archs: tuple[str, ...], ptxas: str | None, force: bool) -> None:
    """Compile Cycles' CUDA kernels for GPUs bpy ships no binary for (H100, H200: sm_90) into visualenv's kernel cache
    ($XDG_CACHE_HOME/visualenv/cycles), once, so that a machine that starts with that cache renders its first GPU frame
    in seconds rather than minutes. Needs the CUDA toolkit's ptxas, no GPU; bpy's own files stay as installed."""
    import time

    from visualenv.compat.blender import cached_kernels
    from visualenv.render.blender.cuda_kernels import compile_cuda_kernels, find_ptxas
    from visualenv.render.blender.devices import nvidia_archs, shipped_cuda_archs

    archs = archs or nvidia_archs()
    if not archs:
        raise click.UsageError("no NVIDIA GPU found here (nvidia-smi): name the architecture, e.g. --arch sm_90")
    shipped = shipped_cuda_archs()
    cached = cached_kernels()
    tool = find_ptxas(ptxas)
    for arch in archs:
        if arch in shipped:
            click.echo(f"{arch}: bpy already has its binary")
            continue
        if arch in cached and not force:
            click.echo(f"{arch}: already compiled, {cached[arch]} (--force compiles it again)")
            continue
        click.echo(f"{arch}: compiling Cycles' kernels with {tool} (minutes: 433 s of one core for sm_90)...")
        started = time.perf_counter()
        path = compile_cuda_kernels(arch, ptxas=tool)
        click.echo(f"{arch}: {path} ({path.stat().st_size / 2**20:.1f} MB) in {time.perf_counter() - started:.0f} s")


@main.command("bench-rllib")
@click.argument("spec")
@click.option("--envs", default=2, show_default=True, type=click.IntRange(min=1), help="envs on each side (RLlib: one runner each)")
@click.option("--steps", default=200, show_default=True, type=click.IntRange(min=1), help="measured steps per env (after a warm-up)")
@click.option("--json", "json_out", type=click.Path(dir_okay=False), help="also write the figures as JSON")
@_friendly
def bench_rllib(spec: str, envs: int, steps: int, json_out: str | None) -> None:
    """Env steps/s through RLlib's EnvRunners vs SB3's SubprocVecEnv (same spec, same envs); memory per runner; time to first sample."""
    try:
        from visualenv.tools.bench_rllib import as_dict, bench_rllib as run_bench
    except ImportError as exc:
        raise click.UsageError(f"bench-rllib needs Ray RLlib: pip install 'visualenv[ray]' ({exc})") from None
    import logging

    logging.getLogger("ray.rllib").setLevel(logging.ERROR)
    figures = run_bench(spec, envs=envs, steps=steps)
    for line in figures.lines():
        click.echo(line)
    if json_out:
        Path(json_out).write_text(json.dumps(as_dict(figures), indent=2) + "\n")


if __name__ == "__main__":  # pragma: no cover
    main()
