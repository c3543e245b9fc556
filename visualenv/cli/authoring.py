"""`visualenv validate`, `schema`, `build`, `inspect`, `init` and `preview`: writing a spec and seeing what it makes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from visualenv.cli.group import shown_option, friendly, main, trust_code_option
from visualenv.errors import SpecError, VisualEnvError


@main.command()
@click.argument("specs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@friendly
def validate(specs: tuple[str, ...]) -> None:
    """Check spec files (format, names, expressions); prints "ok" for each valid file.

    Nothing a spec names is imported: a dynamics.python reference is checked by its form only, and the line says so.
    """
    from visualenv.compiler.program import compile_spec
    from visualenv.spec.loader import load_spec

    problems: list[Any] = []
    for path in specs:
        try:
            target = compile_spec(load_spec(path)).spec.dynamics.python
        except SpecError as exc:
            problems.extend(exc.diagnostics)
            continue
        note = (
            f" (dynamics.python '{target}' checked by its form only, not imported: making the env imports it, "
            "which needs --trust-code)"
            if target
            else ""
        )
        click.echo(("ok" if len(specs) == 1 else f"{path}: ok") + note)
    if problems:
        raise SpecError(problems)


@main.command()
@friendly
def schema() -> None:
    """Print the JSON Schema of the spec format (for editors)."""
    from visualenv.spec.schema import spec_json_schema

    click.echo(json.dumps(spec_json_schema(), indent=2))


@main.command()
@click.argument("spec", type=click.Path(dir_okay=False))
@shown_option(
    "-o", "--out", "out_dir", default="build", type=click.Path(file_okay=False), help="parent folder of the build"
)
@shown_option("--seed", default=0, type=click.IntRange(min=0), help="seed of the previewed reset")
@click.option("--device", type=click.Choice(["cpu", "gpu", "auto"]), default=None, help="override render.device")
@click.option("--quiet", is_flag=True, help="do not print the observation preview")
@trust_code_option
@friendly
def build(spec: str, out_dir: str, seed: int, device: str | None, quiet: bool, trust_code: bool) -> None:
    """Validate and compile SPEC, build its Blender scene, render a preview.

    Writes build/<Id>/env.json (resolved spec, versions, hash), scene.blend
    (opens in Blender) and preview.png (observation beside the high-res view).
    An earlier build is replaced only when the new one succeeded.
    """
    from visualenv.tools.build import build_env

    result = build_env(spec, out_dir, seed=seed, device=device, trust_code=trust_code)
    click.echo(f"built {result.env_id} in {result.seconds:.1f} s -> {result.folder}/")
    for line in result.summary:
        click.echo("  " + line)
    if not quiet and result.ascii_preview:
        click.echo(f"observation (reset, seed {seed}{'; ' + result.ascii_note if result.ascii_note else ''}):")
        click.echo(result.ascii_preview)


@main.command()
@click.argument("blend", type=click.Path(exists=True, dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="print the report as JSON (for tools)")
@friendly
def inspect(blend: str, as_json: bool) -> None:
    """What BLEND holds for a spec: scenes, cameras, lights, meshes, materials, animation, and what the spec overrides.

    Given an MJCF model (.xml), the names its expressions can read: joints, bodies, sites, sensors, actuators, geoms.

    The file is read in a child process: a file that crashes Blender is reported, not fatal.
    """
    from visualenv.tools.mjcf_starter import is_mjcf, mjcf_report
    from visualenv.tools.starter import format_report

    if is_mjcf(Path(blend)):  # an MJCF model: the names expressions can read (docs/physics.md), no Blender needed
        click.echo(mjcf_report(Path(blend)))
        return
    from visualenv.render.blender.scene import blendfile

    info = blendfile.describe(_blend_path(blend))
    click.echo(json.dumps(info, indent=1, ensure_ascii=False) if as_json else format_report(info))


@main.command()
@click.argument("blend", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-o",
    "--out",
    "out_path",
    default=None,
    type=click.Path(dir_okay=False),
    help="spec file to write [default: <blend name>.yaml here]",
)
@click.option("--force", is_flag=True, help="replace an existing spec file")
@friendly
def init(blend: str, out_path: str | None, force: bool) -> None:
    """Write a starter spec over BLEND that builds as it is: the file's scene, its first camera, placeholder state, actions and dynamics.

    Given an MJCF model (.xml): MuJoCo physics, actions from its actuators, a camera that frames it, its names as comments.
    """
    from visualenv.render.blender.scene import blendfile
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
    from visualenv.render.blender.scene.blendfile import is_blend_file

    path = Path(blend)
    if not is_blend_file(path):
        raise VisualEnvError(f"not a Blender file: {path} (a .blend saved by Blender is needed)")
    return path


@main.command()
@click.argument("spec", type=click.Path())
@shown_option("-o", "--out", "out_dir", default="frames", type=click.Path(file_okay=False))
@shown_option("--steps", default=20, type=click.IntRange(min=1), help="steps of the random episode")
@shown_option("--seed", default=0, type=click.IntRange(min=0))
@trust_code_option
@friendly
def preview(spec: str, out_dir: str, steps: int, seed: int, trust_code: bool) -> None:
    """Save a few frames (observation beside the high-res view) of a random episode."""
    from visualenv.tools.build import preview_frames

    paths = preview_frames(spec, out_dir, steps=steps, seed=seed, progress=True, trust_code=trust_code)
    click.echo(f"wrote {len(paths)} frames to {out_dir}/")
