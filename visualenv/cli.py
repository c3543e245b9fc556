"""The `visualenv` command: validate, build, preview, schema, bench, train, play.

Bad input never shows a traceback: spec problems print as
``file:line:column: field: message`` lines and exit with status 2.
"""

from __future__ import annotations

import functools
import json
import sys
from pathlib import Path
from typing import Any, Callable

import click

from visualenv.errors import SpecError, VisualEnvError

EXIT_INVALID = 2


def _friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn visualenv's own errors into messages and exit codes."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except SpecError as exc:
            for diagnostic in exc.diagnostics:
                click.echo(str(diagnostic), err=True)
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
@click.option("--out", "out_dir", default="build", show_default=True, type=click.Path(file_okay=False), help="parent folder of the build")
@click.option("--seed", default=0, show_default=True, help="seed of the previewed reset")
@click.option("--device", type=click.Choice(["cpu", "gpu", "auto"]), default=None, help="override render.device")
@click.option("--quiet", is_flag=True, help="do not print the observation preview")
@_friendly
def build(spec: str, out_dir: str, seed: int, device: str | None, quiet: bool) -> None:
    """Validate and compile SPEC, build its Blender scene, render a preview.

    Writes build/<Id>/env.json (resolved spec, versions, hash), scene.blend
    (opens in Blender) and preview.png (observation beside the high-res view).
    An earlier build is replaced only when the new one succeeded.
    """
    from visualenv.build import build_env

    result = build_env(spec, out_dir, seed=seed, device=device)
    click.echo(f"built {result.env_id} in {result.seconds:.1f} s -> {result.folder}/")
    for line in result.summary:
        click.echo("  " + line)
    if not quiet and result.ascii_preview:
        click.echo("observation (reset, seed %d):" % seed)
        click.echo(result.ascii_preview)


@main.command()
@click.argument("spec", type=click.Path())
@click.option("--out", "out_dir", default="frames", show_default=True, type=click.Path(file_okay=False))
@click.option("--steps", default=20, show_default=True, help="steps of the random episode")
@click.option("--seed", default=0, show_default=True)
@_friendly
def preview(spec: str, out_dir: str, steps: int, seed: int) -> None:
    """Save a few frames (observation beside the high-res view) of a random episode."""
    from visualenv.build import preview_frames

    paths = preview_frames(spec, out_dir, steps=steps, seed=seed)
    click.echo(f"wrote {len(paths)} frames to {out_dir}/")


if __name__ == "__main__":  # pragma: no cover
    main()
