"""`visualenv bench`, `info`, `compile-kernels` and `bench-rllib`: what this machine does with visualenv."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click
from click.core import ParameterSource

from visualenv.cli.group import (
    shown_option,
    check_writable,
    friendly,
    main,
    refuse_code_without_consent,
    trust_code_option,
    worker_counts,
)
from visualenv.render.base import READBACKS


def _bench_batched(
    specs: tuple[str, ...],
    sizes: tuple[int, ...],
    steps: int,
    cores: int,
    autoreset: str,
    results: list[Any],
    split: tuple[int, ...] | None = None,
    device: str | None = None,
    trust_code: bool = False,
) -> None:
    """`bench --batched`: each batch size in a fresh process (or in K workers each, `split`), then the per-process
    vector env with one worker per usable core."""
    from visualenv.tools.bench import bench_parallel
    from visualenv.tools.bench_batch import bench_batched, lines

    for k in split or ():
        if not 1 <= k <= min(sizes):
            raise click.BadParameter(
                f"with --batched, each count of workers must be from 1 to the smallest batch size ({min(sizes)}): "
                f"each worker holds a batch of at least one env, got {k}",
                param_hint="--workers",
            )
    for spec in specs:
        batches = bench_batched(
            spec, sizes, steps, autoreset=autoreset, workers=split or (None,), device=device, trust_code=trust_code
        )
        workers = max(2, cores)
        per_process = bench_parallel(spec, workers, steps, 0, 0.0, device=device, trust_code=trust_code)
        click.echo(f"{spec}")
        for line in lines(batches, per_process):
            click.echo(line)
        results.append({"spec": spec, "batched": batches, "per_process": per_process})


def _bench_phases(
    specs: tuple[str, ...],
    steps: int,
    readback: str,
    threads: int | None,
    device: str | None,
    trust_code: bool,
    results: list[Any],
) -> None:
    """`bench --phases`: each spec's phase record, then the table of them all."""
    from visualenv.tools.bench_phases import bench_phases, table

    for spec in specs:
        click.echo(
            f"{spec}: {steps} steps, every other one recorded, then the shader copies at {max(1, steps // 2)} states"
        )
        results.append(
            bench_phases(spec, steps, readback=readback, threads=threads, device=device, trust_code=trust_code)
        )
    for line in table(results):
        click.echo(line)


@main.command()
@click.argument("specs", nargs=-1, required=True)
@shown_option("--steps", default=500, type=click.IntRange(min=1), help="measured env steps (after a warm-up)")
@click.option(
    "--workers",
    default="2",
    show_default=True,
    callback=lambda ctx, param, value: worker_counts(value),
    help="parallel envs for the parallel figure (0: skip); a list such as 1,2,4,8 measures scaling against one confined worker; "
    "with --batched: K worker processes sharing each batch size (a list such as 1,2 measures each)",
)
@click.option(
    "--threads", type=click.IntRange(min=1), default=None, help="render threads of the single env (default: all cores)"
)
@shown_option(
    "--readback",
    default="auto",
    type=click.Choice(READBACKS),
    help="how pixels leave Blender (file: the BMP path, for before/after comparisons)",
)
@shown_option("--pin/--no-pin", default=True, help="confine each parallel worker to its own cores")
@click.option(
    "--soak",
    "soak_steps",
    type=click.IntRange(min=0),
    default=0,
    help="also run this many steps and report memory growth (e.g. 50000)",
)
@click.option(
    "--batched",
    "batch_sizes",
    default=None,
    callback=lambda ctx, param, value: value and worker_counts(value, "--batched"),
    help="batch sizes such as 1,16,64: N envs in one Blender against the per-process vector env (one worker per core)",
)
@shown_option(
    "--autoreset",
    default="next_step",
    type=click.Choice(["next_step", "same_step"]),
    help="with --batched: when an ended env is reset (same_step: as SB3's VecEnvs and train --batched do)",
)
@click.option(
    "--device",
    type=click.Choice(["cpu", "gpu"]),
    default=None,
    help="render on this device (default: the spec's render.device)",
)
@click.option(
    "--phases",
    is_flag=True,
    help="instead: where a rendered step's time goes (env, scene update, Cycles' sync, BVH, path tracing, film, "
    "readback) and what making the floor, skybox or bodies plain diffuse saves; one row per spec (docs/performance.md)",
)
@click.option("-o", "--json", "json_out", type=click.Path(dir_okay=False), help="also write the figures as JSON")
@trust_code_option
@friendly
def bench(
    specs: tuple[str, ...],
    steps: int,
    workers: tuple[int, ...],
    threads: int | None,
    readback: str,
    pin: bool,
    soak_steps: int,
    batch_sizes: tuple[int, ...] | None,
    autoreset: str,
    device: str | None,
    phases: bool,
    json_out: str | None,
    trust_code: bool,
) -> None:
    """Measure steps/s, render time, overhead vs the raw render floor, memory, parallel speed-up (--phases: where a
    step's time goes)."""
    import platform

    import psutil

    from visualenv.tools.bench import as_dict, bench_one
    from visualenv.env.cores import usable_cores

    if phases and batch_sizes:
        raise click.BadParameter("--phases splits one env's step; it does not take --batched", param_hint="--phases")
    if json_out:
        check_writable(json_out, "--json")
    for spec in specs:
        refuse_code_without_consent(spec, trust_code)
    cores = len(usable_cores())
    machine_cores = psutil.cpu_count() or cores
    click.echo(
        f"machine: {platform.processor() or platform.machine()}, {machine_cores} cores"
        f"{f' ({cores} usable by this process)' if cores != machine_cores else ''}, "
        f"{psutil.virtual_memory().total / 2**30:.0f} GiB, Python {platform.python_version()}"
    )
    results: list[Any] = []
    if phases:
        _bench_phases(specs, steps, readback, threads, device, trust_code, results)
    elif batch_sizes:
        split = (
            workers
            if click.get_current_context().get_parameter_source("workers") is ParameterSource.COMMANDLINE
            else None
        )
        _bench_batched(specs, batch_sizes, steps, cores, autoreset, results, split, device, trust_code)
    for spec in specs if not (batch_sizes or phases) else ():
        single, scaling = (workers[0], ()) if len(workers) == 1 else (0, workers)
        figures = bench_one(
            spec,
            steps,
            workers=single,
            soak_steps=soak_steps,
            threads=threads,
            readback=readback,
            pin=pin,
            scaling=scaling,
            device=device,
            trust_code=trust_code,
        )
        for line in figures.lines():
            click.echo(line)
        results.append(as_dict(figures))
    if json_out:
        Path(json_out).write_text(json.dumps(results, indent=2) + "\n")


@main.command()
@click.option("--json", "as_json", is_flag=True, help="print the report as JSON")
@click.option(
    "--warm-gpu",
    is_flag=True,
    help="render one Cycles GPU frame now, so the driver compiles and caches the kernels before training",
)
@friendly
def info(as_json: bool, warm_gpu: bool) -> None:
    """Versions, usable cores, and what Blender can render on here: Cycles devices per backend, EEVEE/Workbench's context, kernel caches."""
    from visualenv.tools.info import format_report, gather

    report = gather(warm_gpu=warm_gpu)
    click.echo(json.dumps(report, indent=2) if as_json else format_report(report))


@main.command("compile-kernels")
@click.option(
    "--arch",
    "archs",
    multiple=True,
    help="CUDA architecture such as sm_90 (repeatable; default: this machine's NVIDIA GPUs)",
)
@click.option(
    "--ptxas",
    type=click.Path(dir_okay=False),
    default=None,
    help="the CUDA toolkit's ptxas (default: PATH, $CUDA_HOME, /usr/local/cuda)",
)
@click.option(
    "--force", is_flag=True, help="compile again where the kernel cache already holds the architecture's binary"
)
@friendly
def compile_kernels(archs: tuple[str, ...], ptxas: str | None, force: bool) -> None:
    """Compile Cycles' CUDA kernels for GPUs bpy ships no binary for (H100, H200: sm_90) into visualenv's kernel cache
    ($XDG_CACHE_HOME/visualenv/cycles), once, so that a machine that starts with that cache renders its first GPU frame
    in seconds rather than minutes. Needs the CUDA toolkit's ptxas, no GPU; bpy's own files stay as installed."""
    import time

    from visualenv.compat.blender import cached_kernels
    from visualenv.render.blender.runtime.cuda_kernels import compile_cuda_kernels, find_ptxas
    from visualenv.render.blender.runtime.devices import nvidia_archs, shipped_cuda_archs

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
@shown_option("--envs", default=2, type=click.IntRange(min=1), help="envs on each side (RLlib: one runner each)")
@shown_option("--steps", default=200, type=click.IntRange(min=1), help="measured steps per env (after a warm-up)")
@click.option("--json", "json_out", type=click.Path(dir_okay=False), help="also write the figures as JSON")
@trust_code_option
@friendly
def bench_rllib(spec: str, envs: int, steps: int, json_out: str | None, trust_code: bool) -> None:
    """Env steps/s through RLlib's EnvRunners vs SB3's SubprocVecEnv (same spec, same envs); memory per runner; time to first sample."""
    try:
        from visualenv.tools.bench_rllib import as_dict, bench_rllib as run_bench
    except ImportError as exc:
        raise click.UsageError(f"bench-rllib needs Ray RLlib: pip install 'visualenv[ray]' ({exc})") from None
    import logging

    logging.getLogger("ray.rllib").setLevel(logging.ERROR)
    refuse_code_without_consent(spec, trust_code)
    figures = run_bench(spec, envs=envs, steps=steps, trust_code=trust_code)
    for line in figures.lines():
        click.echo(line)
    if json_out:
        Path(json_out).write_text(json.dumps(as_dict(figures), indent=2) + "\n")
