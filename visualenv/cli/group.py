"""The `visualenv` command group and what its commands share: the error handling that keeps tracebacks from users
(spec problems as ``file:line:column: field: message`` lines, exit status 2; other errors one line, status 1), the
options and names several commands take."""

from __future__ import annotations

import functools
import sys
from pathlib import Path
from typing import Any, Callable

import click

from visualenv.compat.glibc import apply_policy
from visualenv.errors import SpecError, VisualEnvError

#: the SB3 algorithms `train` and `play` take (training.algorithm_class maps them to classes)
ALGORITHMS = ("ppo", "a2c", "dqn", "sac")


EXIT_INVALID = 2


RANDOM = "random"  # eval --model's name for uniform random actions (the baseline)


MODEL_HELP = (
    "a policy file (policy.safetensors with its policy.json, as export-policy and train write) or 'pretrained' (the shipped "
    "agent, results/<Id>/policy.safetensors; 'pretrained:NAME': results/<Id>/NAME/'s){}; a .zip, .pt or RLlib checkpoint folder only with --trust-pickle"
)


def shown_option(*decls: str, default: Any, type: Any = None, help: str | None = None) -> Callable[..., Any]:
    """An option whose default its help shows (``show_default=True``), as most of the commands' options are."""
    return click.option(*decls, default=default, show_default=True, type=type, help=help)


trust_pickle_option = click.option(
    "--trust-pickle",
    is_flag=True,
    help="also load pickle-based models (SB3 .zip, torch .pt/.pth, RLlib checkpoint folders): unpickling runs whatever code the file "
    "holds, so only for files you trust (docs/security.md)",
)

trust_code_option = click.option(
    "--trust-code",
    is_flag=True,
    help="import the module a spec's dynamics.python names: importing it runs its code, so only for specs whose author "
    "you trust (docs/security.md); a spec without dynamics.python needs no flag",
)


def refuse_code_without_consent(spec: str, trust_code: bool) -> None:
    """The consent error of a spec with ``dynamics.python`` given without --trust-code, raised before a command
    starts processes or writes files (the envs it makes refuse too, later)."""
    from visualenv.compiler.python_hook import refuse_untrusted_code
    from visualenv.env.registration import resolve
    from visualenv.spec.loader import load_spec

    refuse_untrusted_code(load_spec(resolve(spec)), trust_code)


def friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
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


def model_file(spec: str, value: str) -> str:
    """--model: a model file or checkpoint folder, or 'pretrained' ('pretrained:NAME') for a shipped agent of the spec's env."""
    from visualenv.train.model_files import PRETRAINED, is_pretrained, pretrained_model

    if is_pretrained(value):
        from visualenv.env.registration import resolve
        from visualenv.spec.loader import load_spec

        return str(pretrained_model(load_spec(resolve(spec)).spec.id, value))
    if not Path(value).exists():  # a file, or an RLlib checkpoint folder: load_model tells which it is not
        raise click.BadParameter(
            f"{value}: no such file (or '{PRETRAINED}' for the shipped agent)", param_hint="--model"
        )
    return value


def check_writable(path: str, option: str) -> None:
    """A figure file that cannot be written is refused now, not after minutes of measuring (its folder is made).

    A file that was not there is removed again, so a run that fails later leaves no empty file behind."""
    from visualenv.files import make_dir

    try:
        make_dir(Path(path).parent)
        existed = Path(path).exists()
        Path(path).touch()
        if not existed:
            Path(path).unlink()
    except (OSError, VisualEnvError) as exc:
        raise click.BadParameter(
            f"cannot write {path}: {getattr(exc, 'strerror', None) or exc}", param_hint=option
        ) from None


def worker_counts(value: str, option: str = "--workers") -> tuple[int, ...]:
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


def difficulty(value: str | None, option: str = "--distractions") -> float | list[float] | dict[str, Any] | None:
    """--distractions: a difficulty in [0, 1], a Distracting Control Suite level by name, a range LOW:HIGH (each
    episode's difficulty drawn uniformly in it), or a spec's ``distractions:`` section as a YAML mapping
    (``{difficulty: 0.2, background: {videos: DIR}}``), checked here as the spec's section is."""
    from visualenv.spec.options import DISTRACTION_LEVELS

    if value is None:
        return None
    if value in DISTRACTION_LEVELS:
        return DISTRACTION_LEVELS[value]
    if value.lstrip().startswith("{"):
        return _distractions_section(value, option)
    try:
        bounds = [float(part) for part in value.split(":")]
    except ValueError:
        bounds = []
    if len(bounds) not in (1, 2) or not all(0.0 <= b <= 1.0 for b in bounds) or bounds != sorted(bounds):
        raise click.BadParameter(
            f"{value!r}: expected a difficulty from 0 to 1, {', '.join(DISTRACTION_LEVELS)}, a range LOW:HIGH, "
            "or a distractions section as a mapping ({difficulty: 0.2, ...})",
            param_hint=option,
        )
    return bounds[0] if len(bounds) == 1 else bounds


def _distractions_section(value: str, option: str) -> dict[str, Any]:
    """A ``distractions:`` section given as YAML flow text, refused with the spec's own messages if a spec would be."""
    import yaml

    from visualenv.spec.options import check_make_options

    try:
        section = yaml.safe_load(value)
    except yaml.YAMLError as exc:
        raise click.BadParameter(f"{value!r} is not a YAML mapping: {exc.problem}", param_hint=option) from None
    if not isinstance(section, dict):
        raise click.BadParameter(f"{value!r} is not a YAML mapping", param_hint=option)
    try:
        check_make_options(distractions=section)
    except SpecError as exc:
        problems = "; ".join(f"{d.path}: {d.message}" if d.path else d.message for d in exc.diagnostics)
        raise click.BadParameter(problems, param_hint=option) from None
    return section
