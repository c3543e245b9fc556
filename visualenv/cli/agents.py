"""`visualenv play`, `eval`, `view` and `export-policy`: what a trained agent does, and its policy file."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click
import numpy as np

from visualenv.cli.group import (
    shown_option,
    ALGORITHMS,
    MODEL_HELP,
    RANDOM,
    check_writable,
    difficulty,
    friendly,
    main,
    model_file,
    trust_code_option,
    trust_pickle_option,
)
from visualenv.compat.mkl import compatible_mode
from visualenv.env.registration import resolve
from visualenv.errors import VisualEnvError
from visualenv.spec.loader import load_spec


def _video_path(value: str | None) -> str | None:
    """--record checked as play() checks it, reported as a bad option."""
    from visualenv.train.play import check_recording

    if value is not None:
        try:
            check_recording(value)
        except VisualEnvError as exc:
            raise click.BadParameter(str(exc), param_hint="--record") from None
    return value


@main.command()
@click.argument("spec")
@click.option("--model", "model_path", help=MODEL_HELP.format("") + "  [default: random actions]")
@trust_pickle_option
@shown_option("--algo", default="ppo", type=click.Choice(ALGORITHMS))
@shown_option("--episodes", default=3, type=click.IntRange(min=1))
@shown_option("--seed", default=0, type=click.IntRange(min=0))
@click.option(
    "--record",
    type=click.Path(dir_okay=False),
    callback=lambda ctx, param, value: _video_path(value),
    help="save a .gif, .webp (smallest) or .mp4 of the view beside the observation",
)
@click.option(
    "--view",
    "view_preset",
    type=click.Choice(["fast", "quality"]),
    default=None,
    help="render preset of the recorded view (default: the spec's; 'fast' records in seconds)",
)
@click.option(
    "--view-size", type=click.IntRange(16, 4096), default=None, help="longer side of the recorded view in pixels"
)
@trust_code_option
@friendly
@compatible_mode()  # MKL_CBWR=COMPATIBLE before torch loads: the policy's products alike on every CPU
def play(
    spec: str,
    model_path: str | None,
    trust_pickle: bool,
    algo: str,
    episodes: int,
    seed: int,
    record: str | None,
    view_preset: str | None,
    view_size: int | None,
    trust_code: bool,
) -> None:
    """Run episodes with a random or trained policy; print returns, lengths and success."""
    from visualenv.train.play import play as run_play

    if model_path is not None:
        model_path = model_file(spec, model_path)
    results = run_play(
        spec,
        model_path=model_path,
        algo=algo,
        episodes=episodes,
        seed=seed,
        record=record,
        view_preset=view_preset,
        view_size=view_size,
        trust_pickle=trust_pickle,
        trust_code=trust_code,
    )
    succeeds = load_spec(resolve(spec)).spec.declares_success  # else every episode is 'no success': said nowhere
    for i, ep in enumerate(results):
        success = (", success" if ep.success else ", no success") if succeeds else ""
        click.echo(f"episode {i}: return {ep.ret:.2f}, length {ep.length}{success} ({ep.outcome})")
    mean = f"mean return {np.mean([ep.ret for ep in results]):.2f}, mean length {np.mean([ep.length for ep in results]):.1f}"
    rate = sum(ep.success for ep in results) / len(results)
    click.echo(mean + (f", success {100 * rate:.0f} %" if succeeds else ""))
    if record:
        click.echo(f"recorded {record}")


@main.command("eval")
@click.argument("spec")
@click.option(
    "--model",
    "model_path",
    required=True,
    help=MODEL_HELP.format(", or 'random' (uniform random actions, the baseline)"),
)
@trust_pickle_option
@click.option(
    "--algo",
    type=click.Choice(ALGORITHMS),
    default=None,
    help="the model's algorithm  [default: its run's (config.json), else ppo]",
)
@click.option(
    "--episodes",
    type=click.IntRange(min=1),
    default=None,
    help="deterministic episodes  [default: its run's final evaluation's, else 100]",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0),
    default=None,
    help="seed of the evaluation env  [default: its run's final evaluation's (results.json's eval_seed), else 12884901888, a seed no run trains, selects or reports on]",
)
@click.option(
    "--distractions",
    metavar="D",
    callback=lambda ctx, param, value: difficulty(value),
    default=None,
    help="observations distracted at this difficulty, 0 to 1, easy, medium, hard (0.1, 0.2, 0.3), or LOW:HIGH (drawn per episode) (docs/distractions.md: "
    "camera, colours, background, per episode), or by a distractions section as a YAML mapping ('{difficulty: 0.3, "
    "background: {videos: DIR}}'); new episodes, not compared with results.json",
)
@click.option("-o", "--out", "json_out", type=click.Path(dir_okay=False), help="also write the figures as JSON")
@click.option(
    "--write-results",
    is_flag=True,
    help="record this evaluation as the results.json beside the model (its run's other keys kept): how a shipped file's figures are made",
)
@trust_code_option
@friendly
@compatible_mode()  # MKL_CBWR=COMPATIBLE before torch loads: the policy's products alike on every CPU
def eval_command(
    spec: str,
    model_path: str,
    trust_pickle: bool,
    algo: str | None,
    episodes: int | None,
    seed: int | None,
    distractions: float | list[float] | dict[str, Any] | None,
    json_out: str | None,
    write_results: bool,
    trust_code: bool,
) -> None:
    """Evaluate a trained model (or random actions) on SPEC: mean return, mean length and success rate of deterministic episodes, with 95 % intervals.

    The intervals are a percentile bootstrap of the mean (return, length) and Wilson's
    (success rate). With the seed of the model's run (the default when its results.json
    and config.json lie beside the model, as in runs/<Id>/<time>/ and results/<Id>/),
    the episodes are those of the run's final evaluation and the figures match its results.json:
    bit for bit on a machine like the one that wrote it, else within a stated tolerance (docs/testing.md).
    """
    from visualenv.train.evaluation import (
        TOLERANCE_TEXT,
        differences,
        evaluate_model,
        evaluate_random,
        replays_prefix,
        sample_differences,
        seed_purpose,
    )
    from visualenv.train.reproducible import unlike

    if json_out:
        check_writable(json_out, "--out")
    if distractions is not None and (model_path == RANDOM or write_results):
        raise click.BadParameter(
            "goes with a model's evaluation, not with random actions (state-only) nor --write-results "
            "(results.json holds the undistracted one)",
            param_hint="--distractions",
        )
    if model_path == RANDOM:
        results, recorded = evaluate_random(spec, episodes=episodes, seed=seed, trust_code=trust_code), None
        click.echo(
            f"uniform random actions (the baseline): {results['episodes']} episodes, the first reset with seed {results['eval_seed']}"
        )
    else:
        model_path = model_file(spec, model_path)
        results, recorded = evaluate_model(
            spec,
            model_path,
            algo=algo,
            episodes=episodes,
            seed=seed,
            trust_pickle=trust_pickle,
            distractions=distractions,
            trust_code=trust_code,
        )
        click.echo(
            f"{model_path}: {results['episodes']} deterministic episodes, the first reset with seed {results['eval_seed']}"
            + (
                f", distracted {_distracted(distractions)} (not compared with results.json)"
                if distractions is not None
                else ""
            )
        )
        if distractions is not None:
            recorded = None
    purpose = seed_purpose(results["eval_seed"])
    if purpose in ("training", "selection"):
        click.echo(
            f"note: seed {results['eval_seed']} lies in the {purpose} band: a run seeded near it has seen these episodes "
            "(the defaults play episodes no run trains or selects on)"
        )
    (r_lo, r_hi), (l_lo, l_hi), (s_lo, s_hi) = results["reward_ci95"], results["length_ci95"], results["success_ci95"]
    click.echo(
        f"  mean return   {results['mean_reward']:8.2f}  95 % CI [{r_lo:.2f}, {r_hi:.2f}] (bootstrap), std {results['std_reward']:.2f}"
    )
    click.echo(f"  mean length   {results['mean_length']:8.2f}  95 % CI [{l_lo:.2f}, {l_hi:.2f}] (bootstrap)")
    if load_spec(resolve(spec)).spec.declares_success:  # a spec without a success outcome has none to rate
        click.echo(
            f"  success rate  {100 * results['success_rate']:6.0f} %  95 % CI [{100 * s_lo:.0f} %, {100 * s_hi:.0f} %] (Wilson)"
        )
    matches, comparison, sample = None, None, None
    if (
        recorded is not None
        and recorded.results is not None
        and (recorded.results.get("episodes") == results["episodes"] or replays_prefix(results, recorded.results))
    ):
        other_machine = unlike(recorded.results.get("machine"), results["machine"])
        comparison = "tolerance" if other_machine else "exact"
        if other_machine:
            click.echo(
                f"note: this machine is unlike the one that wrote results.json ({'; '.join(other_machine)}): "
                f"episodes are compared within a tolerance ({TOLERANCE_TEXT}), not bit for bit"
            )
        wrong = differences(results, recorded.results, tolerant=bool(other_machine))
        matches = not wrong
        what = (
            "its run's results.json"
            if recorded.results["episodes"] == results["episodes"]
            else f"the first {results['episodes']} episodes of its run's results.json"
        )
        click.echo(
            (f"reproduces {what}" + (" within that tolerance" if other_machine else ""))
            if matches
            else f"differs from {what}: " + "; ".join(wrong[:5])
        )
        # a chaotic episode grows last-digit differences: the episodes are a new sample of the agent's
        if other_machine:
            sample = sample_differences(results, recorded.results)
        if sample is not None and not matches:
            click.echo(
                "as a sample of results.json's episodes (a long chaotic episode does not replay on other kernels): "
                + ("consistent" if not sample else "not consistent: " + "; ".join(sample))
                + " (docs/testing.md, 'Deterministic rendering')"
            )
        if recorded.note:
            click.echo(f"note: {recorded.note}")
    if write_results:
        click.echo(f"wrote {_write_results(results, model_path, spec)}")
    if json_out:
        record = {
            "spec": spec,
            "model": model_path,
            **results,
            "matches_results_json": matches,
            "comparison": comparison,
            "consistent_sample": None if sample is None else not sample,
        }
        Path(json_out).write_text(json.dumps(record, indent=2) + "\n")
        click.echo(f"wrote {json_out}")


def _write_results(results: dict, model_path: str, spec: str) -> Path:
    """`eval --write-results`: the evaluation becomes results.json beside the model; what the run recorded besides the
    figures (selection, steps, wall time) is kept, and `evaluated` says which file and command made them."""
    from visualenv.train.run_folder import read_run, write_results

    if model_path == RANDOM:
        raise click.BadParameter("random actions have no results.json of their own", param_hint="--write-results")
    kept = read_run(Path(model_path).parent).results or {}
    kept.pop("resets_before", None)  # the new evaluation's replay, if it needs one, is in `results`
    command = (
        f"visualenv eval {spec} --model {model_path} --seed {results['eval_seed']} --episodes {results['episodes']}"
    )
    evaluated = {"file": Path(model_path).name, "command": command}
    return write_results(Path(model_path).parent, {**kept, **results, "evaluated": evaluated})


@main.command()
@click.argument("spec")
@click.option(
    "--model",
    "model_path",
    help="an agent plays: a trained model (as `play` takes), or 'pretrained' ('pretrained:NAME'): a shipped agent; default: you play with the keys",
)
@shown_option("--algo", default="ppo", type=click.Choice(ALGORITHMS))
@click.option(
    "--port",
    type=click.IntRange(0, 65535),
    default=None,
    help="[default: 8765, or any free port where it is taken; 0: any free port]",
)
@shown_option(
    "--host", default="127.0.0.1", help="the address to serve on (another than this machine's own: a warning)"
)
@shown_option(
    "--seed", default=0, type=click.IntRange(min=0), help="seed of the first episode (the next ones count up)"
)
@shown_option(
    "--view",
    "view_preset",
    default="fast",
    type=click.Choice(["fast", "quality", "off"]),
    help="the high-resolution view's preset",
)
@shown_option("--view-size", default=320, type=click.IntRange(16, 4096), help="longer side of the view in pixels")
@trust_pickle_option
@trust_code_option
@friendly
def view(
    spec: str,
    model_path: str | None,
    algo: str,
    port: int | None,
    host: str,
    seed: int,
    view_preset: str,
    view_size: int,
    trust_pickle: bool,
    trust_code: bool,
) -> None:
    """Show SPEC live on a local web page: play it with the keys or watch an agent; saving the spec rebuilds it (docs/viewer.md)."""
    from visualenv.viewer.app import serve
    from visualenv.viewer.session import ViewOptions

    serve(
        spec,
        model=model_path,
        algo=algo,
        host=host,
        port=port,
        seed=seed,
        view=ViewOptions(None if view_preset == "off" else view_preset, view_size),
        echo=lambda line: click.echo(line, err=line.startswith("warning")),
        trust_pickle=trust_pickle,
        trust_code=trust_code,
    )


@main.command("export-policy")
@click.argument("model", type=click.Path(exists=True))
@click.argument("out", type=click.Path(dir_okay=False))
@trust_pickle_option
@shown_option("--algo", default="ppo", type=click.Choice(ALGORITHMS), help="the algorithm of an SB3 .zip")
@click.option("--float32", "full", is_flag=True, help="keep float32 weights (default: float16, half the size)")
@click.option("--force", is_flag=True, help="replace OUT.safetensors and OUT.json where they exist")
@friendly
def export_policy(model: str, out: str, trust_pickle: bool, algo: str, full: bool, force: bool) -> None:
    """Write the policy of a trained model as a policy file: OUT.safetensors (its weights) and OUT.json (what builds the
    network), without the optimizer's state; what the shipped agents in results/ are.

    MODEL: an SB3 .zip, a torch .pt or an RLlib checkpoint folder (with --trust-pickle: loading them runs whatever code
    they hold), or a policy file. `play`, `eval` and `--model` then load OUT without unpickling anything (docs/security.md).
    """
    from visualenv.train.model_files import export_policy as write
    from visualenv.train.policy_format import WEIGHTS

    if Path(out).suffix != WEIGHTS:
        raise click.BadParameter(
            f"expected a file ending in {WEIGHTS} (its .json is written beside it)", param_hint="OUT"
        )
    path = write(model, out, algo=algo, half=not full, trust_pickle=trust_pickle, force=force)
    click.echo(
        f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB, {'float32' if full else 'float16'} weights) and {path.with_suffix('.json').name}"
    )


def _distracted(distractions: float | list[float] | dict[str, Any]) -> str:
    """How the evaluation's observations are distracted, in words: at a difficulty, or by the section given."""
    if isinstance(distractions, dict):
        return f"by {json.dumps(distractions)}"
    return f"at difficulty {distractions}"
