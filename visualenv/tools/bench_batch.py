"""`visualenv bench --batched 1,16,64`: N envs in one Blender against one process per env, and where a batch's step goes.

Each batch size runs in a fresh process (its memory is its own) and reports,
per step of all N envs: env-steps/s, the dynamics (the vectorised step), the
bindings computed for the N envs, their writes into the scene (the copies'
setters and the instances' attributes), Blender's render call, the part of that
call spent updating the moved scene (the call minus the same call with nothing
moved; the scene update is the writes plus this part), the readback and cut into tiles, render calls per step (more than one
where an image is split, or where ``--autoreset same_step`` renders the envs it
reset again), and resident memory per env. The
per-process vector env (one Blender per worker, as many workers as usable
cores) runs beside it for comparison. ``--workers K`` splits each size among K worker
processes (:class:`~visualenv.env.batch_workers.MultiBatchVectorEnv`), timed as a whole.
Figures only: nothing is asserted.
"""

from __future__ import annotations

import multiprocessing
import time
from typing import Any

import numpy as np

from visualenv.compat.glibc import apply_policy


def _median_ms(times: list[float]) -> float:
    return 1000 * float(np.median(times)) if times else 0.0


def measure_batch(
    spec: str,
    n: int,
    steps: int,
    seed: int = 0,
    autoreset: str = "next_step",
    instanced: bool = True,
    device: str | None = None,
    trust_code: bool = False,
) -> dict[str, Any]:
    """One batch of `n` envs: build, warm up, time `steps` steps (run it in a fresh process for its memory).

    ``instanced=False`` copies every object, as batches did before instanced copies (for before/after figures).
    ``device`` ("cpu" or "gpu") overrides the spec's render device.
    """
    import psutil

    from visualenv.env.batch import BATCH_BACKEND, BatchedVectorEnv
    from visualenv.render.blender import BlenderRenderer
    from visualenv.render.frames import Frames
    from visualenv.render.profile import Profile
    from visualenv.tools.bench import device_option

    process = psutil.Process()
    before = process.memory_info().rss
    start = time.perf_counter()
    backend = BATCH_BACKEND if instanced else f"{__name__}:copied_renderer"
    env = BatchedVectorEnv(
        spec,
        n,
        autoreset_mode=autoreset,
        renderer_options=device_option(device),
        backend=backend,
        trust_code=trust_code,
    )
    env.reset(seed=seed)
    build_s = time.perf_counter() - start
    rng = np.random.default_rng(seed)
    env.action_space.seed(int(rng.integers(2**31)))
    for _ in range(5):
        env.step(env.action_space.sample())
    renderer = env.renderer
    profile = Profile()
    env.profile = renderer.profile = profile  # the public hooks: the step's phases, the renderer's
    start = time.perf_counter()
    for _ in range(steps):
        env.step(env.action_space.sample())
    elapsed = time.perf_counter() - start
    env.profile = renderer.profile = None  # the renders below are not steps
    times = profile.times
    still: list[float] = []
    assert isinstance(renderer, BlenderRenderer)  # Blender's render call with the scene as it is: raw_render
    for _ in range(max(3, min(steps, 20))):  # the same call with nothing moved: Blender's floor for this image
        t = time.perf_counter()
        renderer.raw_render()
        still.append(time.perf_counter() - t)
    alone: list[float] = []
    frames = Frames(env.binding_table(), envs=[0])
    for _ in range(6):  # env 0's observation again, as a reset env's (the first call may make its camera)
        t = time.perf_counter()
        renderer.render(frames)
        alone.append(time.perf_counter() - t)
    rss = process.memory_info().rss
    env.close()
    render = _median_ms(times["render"])
    write = 1000 * sum(times["write"]) / steps  # per step: the copies' writes once, the instances' once per camera
    return {
        "envs": n,
        "steps_per_s": steps * n / elapsed,
        "step_ms": 1000 * elapsed / steps,
        "build_s": build_s,
        "dynamics_ms": _median_ms(times["dynamics"]),
        "bind_ms": _median_ms(times["bind"]),
        "write_ms": write,
        "render_ms": render,
        "scene_update_ms": max(0.0, render - _median_ms(still)),
        "instanced": instanced,
        "readback_ms": _median_ms(times["readback"]),
        "alone_ms": _median_ms(alone[1:]),
        "calls_per_step": len(times["render"]) / steps,
        "autoreset": autoreset,
        "rss_mb": rss / 2**20,
        "mb_per_env": rss / 2**20 / n,
        "python_mb": before / 2**20,
    }


def copied_renderer(plan: Any, options: Any, *, num_envs: int) -> Any:
    """The batch renderer that copies every object (no instances), as a backend entry point: the figures before."""
    from visualenv.render.blender.batch.renderer import BatchedBlenderRenderer

    return BatchedBlenderRenderer(plan, options, num_envs=num_envs, instanced=False)


def _in_child(
    spec: str, n: int, steps: int, seed: int, autoreset: str, device: str | None, queue: Any, trust_code: bool = False
) -> None:
    apply_policy()  # a process visualenv started: freed memory kept for the next render call (visualenv.compat.glibc)
    try:
        queue.put(measure_batch(spec, n, steps, seed, autoreset, device=device, trust_code=trust_code))
    except BaseException as exc:  # noqa: BLE001 - reported by the parent, which goes on with the next size
        queue.put({"envs": n, "error": f"{type(exc).__name__}: {exc}"})


def measure_workers(
    spec: str,
    n: int,
    workers: int,
    steps: int,
    seed: int = 0,
    autoreset: str = "next_step",
    device: str | None = None,
    trust_code: bool = False,
) -> dict[str, Any]:
    """`n` envs as `workers` batches in worker processes (MultiBatchVectorEnv): env-steps/s and the workers' memory.

    The stages of a step happen in the workers, so only the whole step is timed here.
    """
    import psutil

    from visualenv.env.batch_workers import MultiBatchVectorEnv
    from visualenv.tools.bench import device_option

    start = time.perf_counter()
    env = MultiBatchVectorEnv(spec, n, workers, autoreset_mode=autoreset, **device_option(device, trust_code))
    try:
        env.reset(seed=seed)
        build_s = time.perf_counter() - start
        env.action_space.seed(seed)
        for _ in range(5):
            env.step(env.action_space.sample())
        start = time.perf_counter()
        for _ in range(steps):
            env.step(env.action_space.sample())
        elapsed = time.perf_counter() - start
        rss = sum(psutil.Process(p.pid).memory_info().rss for p in env.processes)
    finally:
        env.close()
    return {
        "envs": n,
        "workers": workers,
        "steps_per_s": steps * n / elapsed,
        "step_ms": 1000 * elapsed / steps,
        "build_s": build_s,
        "autoreset": autoreset,
        "rss_mb": rss / 2**20,
        "mb_per_env": rss / 2**20 / n,
    }


def _result_of(child: Any, queue: Any, n: int) -> dict[str, Any]:
    """The child's figures, or its death reported (a crashed Blender, a GPU driver that failed) instead of waiting forever."""
    import queue as queues

    while True:
        try:
            return queue.get(timeout=1.0)
        except queues.Empty:
            if not child.is_alive() and queue.empty():
                return {"envs": n, "error": f"the measuring process died (exit code {child.exitcode})"}


def bench_batched(
    spec: str,
    sizes: tuple[int, ...],
    steps: int,
    seed: int = 0,
    autoreset: str = "next_step",
    workers: tuple[int | None, ...] = (None,),
    device: str | None = None,
    trust_code: bool = False,
) -> list[dict[str, Any]]:
    """Each batch size in its own fresh process (`workers` None), or split among K worker processes (each K of `workers`);
    a size that fails is reported, not raised."""
    context = multiprocessing.get_context("spawn")
    out = []
    for n in sizes:
        for k in workers:
            if k is not None:
                try:
                    out.append(measure_workers(spec, n, k, max(1, steps // n), seed, autoreset, device, trust_code))
                except Exception as exc:  # noqa: BLE001 - reported, and the next size goes on
                    out.append({"envs": n, "workers": k, "error": f"{type(exc).__name__}: {exc}"})
                continue
            queue = context.Queue()
            child = context.Process(
                target=_in_child, args=(spec, n, max(1, steps // n), seed, autoreset, device, queue, trust_code)
            )
            child.start()
            out.append(_result_of(child, queue, n))
            child.join()
    return out


def lines(batches: list[dict[str, Any]], per_process: dict[str, Any] | None) -> list[str]:
    """The table `visualenv bench --batched` prints."""
    mode = batches[0].get("autoreset", "next_step") if batches else "next_step"
    rows = [
        f"batched (one process, autoreset {mode}):",
        f"  {'envs':>5} {'env-steps/s':>12} {'step ms':>8} {'dynamics':>9} {'bind':>7} {'write':>7} {'render':>8} {'update':>7} {'readback':>9} "
        f"{'calls':>6} {'alone':>6} {'RSS MB':>7} {'+MB/env':>8} {'build s':>8}",
        "  (ms per step of all envs, medians; write: the bindings written into the scene, per step; render and readback: per call;"
        " update: the render call minus the same call with nothing moved (the scene update is write + update); calls: render calls per step;"
        " alone: env 0's observation re-rendered, as a reset env's is; +MB/env: memory growth per env over the smallest batch)",
    ]
    ok = [b for b in batches if "error" not in b and "workers" not in b]
    smallest = min(ok, key=lambda b: b["envs"]) if ok else None
    split = [b for b in batches if "workers" in b]
    for b in batches:
        if "error" in b and "workers" not in b:
            rows.append(f"  {b['envs']:>5} failed: {b['error']}")
            continue
        if "workers" in b:
            continue
        assert smallest is not None
        growth = (
            (b["rss_mb"] - smallest["rss_mb"]) / (b["envs"] - smallest["envs"])
            if b["envs"] > smallest["envs"]
            else float("nan")
        )
        rows.append(
            f"  {b['envs']:>5} {b['steps_per_s']:>12.1f} {b['step_ms']:>8.1f} {b['dynamics_ms']:>9.2f} {b['bind_ms']:>7.2f} "
            f"{b.get('write_ms', float('nan')):>7.2f} {b['render_ms']:>8.1f} {b['scene_update_ms']:>7.1f} {b['readback_ms']:>9.2f} {b['calls_per_step']:>6.2f} {b.get('alone_ms', float('nan')):>6.1f} {b['rss_mb']:>7.0f} {growth:>8.1f} {b['build_s']:>8.1f}"
        )
    if split:
        rows.append(
            f"batched in K worker processes (one batch of about N/K envs each, confined to its cores; autoreset {mode}):"
        )
        rows.append(
            f"  {'envs':>5} {'K':>3} {'env-steps/s':>12} {'step ms':>8} {'RSS MB':>7} {'MB/env':>7} {'build s':>8}"
        )
        for b in split:
            if "error" in b:
                rows.append(f"  {b['envs']:>5} {b['workers']:>3} failed: {b['error']}")
            else:
                rows.append(
                    f"  {b['envs']:>5} {b['workers']:>3} {b['steps_per_s']:>12.1f} {b['step_ms']:>8.1f} {b['rss_mb']:>7.0f} "
                    f"{b['mb_per_env']:>7.1f} {b['build_s']:>8.1f}"
                )
    if per_process:
        workers = per_process["workers"]
        rows.append(
            f"per-process vector env, {workers} workers (one Blender each): {per_process['steps_per_s']:.1f} env-steps/s, "
            f"{per_process['rss_total_mb'] / workers:.0f} MB per env"
        )
        for b in batches:
            if "error" not in b:
                where = f" in {b['workers']} workers" if "workers" in b else ""
                rows.append(
                    f"  batched {b['envs']}{where}: {b['steps_per_s'] / per_process['steps_per_s']:.2f}x its env-steps/s, "
                    f"{b['rss_mb'] / per_process['rss_total_mb']:.2f}x the memory of its {workers} workers"
                )
    return rows
