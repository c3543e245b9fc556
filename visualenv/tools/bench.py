"""`visualenv bench`: how fast a compiled env delivers observations, and where time goes.

One run measures, on the same built scene:

* the env: steps per second, the render call's time per step (median, p99),
  and the framework overhead: the step's time minus the raw render floor, as a
  share of the step (everything that is not Blender rendering);
* the raw floor: Blender's render call alone (no file written, no readback);
* the same floor with the scene moved before each call as in an episode (bound
  objects, MuJoCo's bodies, cameras and lights): what Blender's update of a
  changed scene (depsgraph, Cycles sync, BVH) adds, which any implementation
  pays and which the framework overhead therefore includes;
* a naive implementation: render to a PNG on disk and load it with Pillow;
* resident memory (peak and final), and optionally a long soak;
* N parallel envs (one Blender process each) through AsyncVectorEnv: the same
  figures, timed inside the workers (:class:`StepTimes`).

Timings vary from run to run on shared machines: this prints figures, it
asserts nothing.
"""

from __future__ import annotations

import gc
import os
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable

import gymnasium as gym
import numpy as np
import psutil

from visualenv.render.frames import Frames
from visualenv.render.profile import Profile


@dataclass
class Figures:
    spec: str
    steps: int
    steps_per_s: float = 0.0
    step_ms_median: float = 0.0
    render_ms_median: float = 0.0
    render_ms_p99: float = 0.0
    floor_ms_median: float = 0.0
    moved_floor_ms_median: float = 0.0
    naive_ms_median: float = 0.0
    overhead_share: float = 0.0
    outside_ms_median: float = 0.0
    outside_share: float = 0.0
    rss_peak_mb: float = 0.0
    rss_final_mb: float = 0.0
    parallel: dict[str, Any] = field(default_factory=dict)
    scaling: list[dict[str, Any]] = field(default_factory=list)
    soak: dict[str, Any] = field(default_factory=dict)

    @property
    def own_overhead_share(self) -> float:
        """The share of a step spent outside Blender: the step minus the moved-scene floor."""
        if not self.step_ms_median:
            return 0.0
        return max(0.0, (self.step_ms_median - self.moved_floor_ms_median) / self.step_ms_median)

    def lines(self) -> list[str]:
        speed_vs_floor = self.floor_ms_median / self.step_ms_median if self.step_ms_median else 0
        speed_vs_naive = self.naive_ms_median / self.step_ms_median if self.step_ms_median else 0
        out = [
            f"{self.spec}: {self.steps} steps, one env",
            f"  env steps/s               {self.steps_per_s:8.1f}",
            f"  step time (median)        {self.step_ms_median:8.2f} ms",
            f"  render call (median/p99)  {self.render_ms_median:8.2f} / {self.render_ms_p99:.2f} ms",
            f"  raw render floor (median) {self.floor_ms_median:8.2f} ms   (render call alone, same scene and settings)",
            f"    with objects moved      {self.moved_floor_ms_median:8.2f} ms   (the same, the scene moved first as in an episode: Blender's update)",
            f"  naive PNG round trip      {self.naive_ms_median:8.2f} ms   (render, write PNG to disk, load it)",
            (
                f"  framework overhead        {100 * self.overhead_share:8.1f} %    of a step (step - raw floor; "
                f"{100 * self.own_overhead_share:.1f} % without Blender's scene update)"
            ),
            f"  outside the render call   {self.outside_ms_median:8.2f} ms   ({100 * self.outside_share:.1f} % of a step: actions, dynamics, bindings, readback)",
            f"  speed vs floor / naive    {speed_vs_floor:8.2f}x / {speed_vs_naive:.2f}x",
            f"  resident memory           {self.rss_peak_mb:8.1f} MB peak, {self.rss_final_mb:.1f} MB final",
        ]
        if self.parallel:
            p = self.parallel
            out += [
                (
                    f"  {p['workers']} parallel envs           {p['steps_per_s']:8.1f} steps/s  ({p['speedup']:.2f}x one env; "
                    f"{p['threads']} render thread(s) each, {'pinned' if p['pinned'] else 'not pinned'})"
                ),
                f"    step in a worker (median) {p['step_ms_median']:6.2f} ms",
                f"    render call (median/p99)  {p['render_ms_median']:6.2f} / {p['render_ms_p99']:.2f} ms",
                f"    outside the render call   {p['outside_ms_median']:6.2f} ms   ({100 * p['outside_share']:.1f} % of a worker's step)",
                (
                    f"    resident memory           {p['rss_peak_mb']:6.1f} MB peak, {p['rss_final_mb']:.1f} MB final per worker "
                    f"({p['rss_total_mb']:.0f} MB for all {p['workers']})"
                ),
            ]
        if self.scaling:
            one = self.scaling[0]
            out.append(f"  scaling: one worker confined to one core (1 render thread) {one['steps_per_s']:.1f} steps/s")
            out.append("    workers   steps/s   vs n x one confined   cores each   render threads   memory per worker")
            for row in self.scaling[1:]:
                out.append(
                    f"    {row['workers']:>7} {row['steps_per_s']:9.1f}   {row['vs_confined']:19.2f}   {row['cores_each']:>10}   "
                    f"{row['threads']:>14}   {row['rss_final_mb']:>10.0f} MB"
                )
        if self.soak:
            s = self.soak
            out.append(
                f"  soak: {s['steps']} steps, {s['resets']} resets: memory {s['rss_start_mb']:.1f} -> {s['rss_end_mb']:.1f} MB "
                f"(growth {s['growth_mb']:+.1f} MB), Blender data blocks {s['blocks_start']} -> {s['blocks_end']}"
            )
        return out


def _rss_mb() -> float:
    return psutil.Process(os.getpid()).memory_info().rss / 2**20


def _peak_rss_mb() -> float:
    """This process's peak resident memory (Linux reports kilobytes, macOS bytes; Windows: the current figure)."""
    try:
        import resource
    except ImportError:  # Windows
        return _rss_mb()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (2**20 if sys.platform == "darwin" else 2**10)


def timed(fn: Callable[..., Any], times: list[float]) -> Callable[..., Any]:
    """`fn`, recording each call's wall time into `times`."""

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            times.append(time.perf_counter() - start)

    return wrapper


def random_actions(env: Any, n: int, seed: int) -> list[Any]:
    env.action_space.seed(seed)
    return [env.action_space.sample() for _ in range(n)]


def run_env(env: Any, actions: list[Any], seed: int) -> list[float]:
    """Step through `actions`, resetting at episode ends; per-step wall times."""
    env.reset(seed=seed)
    times = []
    for action in actions:
        start = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
        times.append(time.perf_counter() - start)
    return times


def blender_data_blocks() -> int:
    import bpy

    return sum(
        len(getattr(bpy.data, kind))
        for kind in ("objects", "meshes", "materials", "images", "scenes", "node_groups", "cameras", "lights", "worlds")
    )


def device_option(device: str | None, trust_code: bool = False) -> dict[str, Any]:
    """The renderer option that renders on `device` ("cpu" or "gpu"), none to keep the spec's render.device; with
    `trust_code`, the consent to import the spec's ``dynamics.python`` (docs/security.md), which make() takes too."""
    return ({"device": device} if device else {}) | ({"trust_code": True} if trust_code else {})


def bench_one(
    spec: str,
    steps: int = 500,
    *,
    seed: int = 0,
    warmup: int = 20,
    floor_renders: int = 200,
    naive_renders: int = 50,
    workers: int = 0,
    soak_steps: int = 0,
    threads: int | None = None,
    readback: str = "auto",
    pin: bool = True,
    scaling: tuple[int, ...] = (),
    device: str | None = None,
    trust_code: bool = False,
) -> Figures:
    from visualenv.env.make import make

    options: dict[str, Any] = {"readback": readback, **device_option(device, trust_code)}
    if threads:
        options["threads"] = threads
    env = StepTimes(make(spec, **options))
    base: Any = env.unwrapped  # the VisualEnv under the wrappers
    figures = Figures(spec=str(spec), steps=steps)
    actions = random_actions(env, warmup + steps, seed)
    run_env(env, actions[:warmup], seed)
    renderer = base.renderer
    env.start_timing()
    gc.collect()
    rss_peak = _rss_mb()
    step_times = run_env(env, actions[warmup:], seed + 1)
    rss_peak = max(rss_peak, _rss_mb())
    timings = env.timings()
    render_times, outside = timings["render"], timings["outside"]
    # the raw floor: Blender's render call alone, same scene and settings as the last observation
    base.renderer.render(Frames((base.binding_values(),)))
    scene = renderer.scene
    floor = render_call_times(scene.name, floor_renders)
    figures.moved_floor_ms_median = 1000 * float(
        np.median(_moved_floor(env, actions[warmup : warmup + floor_renders], seed + 3))
    )
    figures.naive_ms_median = 1000 * float(np.median(_naive_png(scene, naive_renders)))
    total = sum(step_times)
    figures.steps_per_s = steps / total
    figures.step_ms_median = 1000 * float(np.median(step_times))
    figures.render_ms_median = 1000 * float(np.median(render_times))
    figures.render_ms_p99 = 1000 * float(np.percentile(render_times, 99))
    figures.floor_ms_median = 1000 * float(np.median(floor))
    figures.overhead_share = max(0.0, (figures.step_ms_median - figures.floor_ms_median) / figures.step_ms_median)
    figures.outside_ms_median = 1000 * float(np.median(outside))
    figures.outside_share = figures.outside_ms_median / figures.step_ms_median
    if soak_steps:
        figures.soak = soak(env, soak_steps, seed + 2)
    figures.rss_peak_mb = max(rss_peak, _rss_mb())
    figures.rss_final_mb = _rss_mb()
    env.close()
    if workers > 1:
        figures.parallel = bench_parallel(
            spec,
            workers,
            steps,
            seed,
            figures.steps_per_s,
            readback=readback,
            pin=pin,
            device=device,
            trust_code=trust_code,
        )
    if scaling:
        figures.scaling = bench_scaling(
            spec, scaling, steps, seed, readback=readback, pin=pin, device=device, trust_code=trust_code
        )
    return figures


def bench_scaling(
    spec: str,
    counts: tuple[int, ...],
    steps: int,
    seed: int,
    *,
    readback: str = "auto",
    pin: bool = True,
    device: str | None = None,
    trust_code: bool = False,
) -> list[dict[str, Any]]:
    """steps/s of n parallel workers for each n in `counts`, against n times one worker confined to one core.

    The first row is that reference: one worker process on one core with one render thread.
    """
    from visualenv.env.cores import usable_cores

    one = bench_parallel(
        spec,
        1,
        steps,
        seed,
        0.0,
        readback=readback,
        shares=[(usable_cores()[0],)],
        threads=1,
        device=device,
        trust_code=trust_code,
    )
    rows = [one]
    for n in counts:
        row = bench_parallel(
            spec, n, steps, seed, 0.0, readback=readback, pin=pin, device=device, trust_code=trust_code
        )
        row["vs_confined"] = row["steps_per_s"] / (n * one["steps_per_s"])
        rows.append(row)
    return rows


def _moved_floor(env: Any, actions: list[Any], seed: int) -> list[float]:
    """Blender's render call alone after the scene was written as in an episode (bound objects, MuJoCo's bodies and
    cameras moved; the writes and a readback not timed)."""
    base: Any = env.unwrapped  # the VisualEnv under the wrappers
    renderer = base.renderer
    env.reset(seed=seed)
    frames = []
    for action in actions:  # the states of real steps (these renders are not timed)
        _, _, terminated, truncated, _ = env.step(action)
        frames.append(base.frames().copy())
        if terminated or truncated:
            env.reset()
    return render_call_times(renderer.scene.name, len(frames), lambda i: renderer.write(frames[i]))


def render_call_times(scene_name: str, n: int, before: Callable[[int], None] | None = None) -> list[float]:
    """Wall times of `n` bare ``bpy.ops.render.render`` calls; ``before(i)``, untimed, may change the scene first."""
    import bpy

    times = []
    for i in range(n):
        if before is not None:
            before(i)
        start = time.perf_counter()
        bpy.ops.render.render(scene=scene_name)
        times.append(time.perf_counter() - start)
    return times


def _naive_png(scene: Any, renders: int) -> list[float]:
    """Render to a PNG file on disk and read it back with Pillow: the obvious way."""
    import bpy
    from PIL import Image

    from visualenv.render.blender.readback import quiet_stdout

    settings = scene.render.image_settings
    saved = (settings.file_format, settings.color_mode, scene.render.filepath)
    times = []
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "frame.png")
        settings.file_format = "PNG"
        settings.color_mode = "RGB"
        scene.render.filepath = path
        for _ in range(renders):
            start = time.perf_counter()
            with quiet_stdout():
                bpy.ops.render.render(write_still=True, scene=scene.name)
            np.asarray(Image.open(path).convert("L"))
            times.append(time.perf_counter() - start)
    settings.file_format, settings.color_mode, scene.render.filepath = saved
    return times


def soak(env: Any, steps: int, seed: int, report_every: int = 0) -> dict[str, Any]:
    """Many steps and resets: memory and Blender data blocks must stay flat."""
    env.action_space.seed(seed)
    env.reset(seed=seed)
    gc.collect()
    rss_start, blocks_start = _rss_mb(), blender_data_blocks()
    resets = 0
    for i in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
            resets += 1
        if report_every and (i + 1) % report_every == 0:
            print(f"  soak {i + 1}/{steps}: {_rss_mb():.1f} MB, {blender_data_blocks()} data blocks", flush=True)
    gc.collect()
    rss_end = _rss_mb()
    return {
        "steps": steps,
        "resets": resets,
        "rss_start_mb": rss_start,
        "rss_end_mb": rss_end,
        "growth_mb": rss_end - rss_start,
        "blocks_start": blocks_start,
        "blocks_end": blender_data_blocks(),
    }


class StepTimes(gym.Wrapper):
    """Times each step and each Blender render call, in the process the env runs in.

    The parallel figures need what happens in the workers' processes; Gymnasium's
    vector envs reach this wrapper through ``call``: ``vec.call("start_timing")``
    after the warm-up, ``vec.call("timings")`` at the end. The single env uses it directly.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self._steps: list[float] = []
        self._renders: list[float] = []
        self._outside: list[float] = []  # per step: the step's time minus its render calls
        self._timing = False

    def start_timing(self) -> None:
        """Record from now on, into fresh lists (the renderer exists once the env has been reset)."""
        self._stop_timing()
        self._steps, self._renders, self._outside = [], [], []
        profile = Profile()
        self._renders = profile.times["render"]
        self.env.unwrapped.renderer.profile = profile  # type: ignore[attr-defined]  # a VisualEnv's renderer's hook
        self._timing = True

    def step(self, action: Any) -> Any:
        rendered = len(self._renders)
        start = time.perf_counter()
        out = self.env.step(action)
        if self._timing:
            elapsed = time.perf_counter() - start
            self._steps.append(elapsed)
            self._outside.append(elapsed - sum(self._renders[rendered:]))
        return out

    def timings(self) -> dict[str, Any]:
        """What was recorded since :meth:`start_timing`, and stop recording (a long soak must not grow lists)."""
        self._stop_timing()
        return {
            "step": self._steps,
            "render": self._renders,
            "outside": self._outside,
            "rss_mb": _rss_mb(),
            "rss_peak_mb": _peak_rss_mb(),
        }

    def _stop_timing(self) -> None:
        if self._timing:
            self.env.unwrapped.renderer.profile = None  # type: ignore[attr-defined]
            self._timing = False


def bench_parallel(
    spec: str,
    workers: int,
    steps: int,
    seed: int,
    single: float,
    *,
    readback: str = "auto",
    pin: bool = True,
    shares: list[tuple[int, ...] | None] | None = None,
    threads: int | None = None,
    device: str | None = None,
    trust_code: bool = False,
) -> dict[str, Any]:
    """The single env's figures for `workers` envs stepped together (AsyncVectorEnv, one Blender process each).

    Each worker gets its own cores as make_vec gives them (`pin`), or the `shares` given.
    """
    from visualenv.env.cores import render_threads, worker_cores
    from visualenv.env.vector import WorkerVectorEnv, env_factory, with_render_threads

    shares = shares or worker_cores(workers, pin)
    options: dict[str, Any] = {"readback": readback, **device_option(device, trust_code)}
    vec: Any = WorkerVectorEnv(
        [
            env_factory(
                str(spec), cores=share, wrapper_class=StepTimes, **with_render_threads(options, share, workers, threads)
            )
            for share in shares
        ],
        context="spawn",
        shared_memory=True,
    )
    pinned = any(share is not None for share in shares)
    threads = render_threads(shares[0], workers, threads)
    try:
        vec.reset(seed=seed)
        vec.action_space.seed(seed)
        for _ in range(50):  # warm-up: workers build their scenes and Blender's persistent data
            vec.step(vec.action_space.sample())
        vec.call("start_timing")
        rounds = max(1, steps // workers)
        start = time.perf_counter()
        for _ in range(rounds):
            vec.step(vec.action_space.sample())  # autoreset inside
        elapsed = time.perf_counter() - start
        measured = vec.call("timings")
    finally:
        vec.close()
    rate = rounds * workers / elapsed
    step_times = [t for w in measured for t in w["step"]]
    render_times = [t for w in measured for t in w["render"]]
    outside = [t for w in measured for t in w["outside"]]
    step_median = float(np.median(step_times))
    return {
        "workers": workers,
        "threads": threads,
        "pinned": pinned,
        "cores_each": len(shares[0]) if shares[0] else "all",
        "steps_per_s": rate,
        "speedup": rate / single if single else 0.0,
        "step_ms_median": 1000 * step_median,
        "render_ms_median": 1000 * float(np.median(render_times)),
        "render_ms_p99": 1000 * float(np.percentile(render_times, 99)),
        "outside_ms_median": 1000 * float(np.median(outside)),
        "outside_share": float(np.median(outside)) / step_median,
        "rss_peak_mb": max(w["rss_peak_mb"] for w in measured),
        "rss_final_mb": max(w["rss_mb"] for w in measured),
        "rss_total_mb": sum(w["rss_mb"] for w in measured),
        "rss_each_mb": [w["rss_mb"] for w in measured],
    }


def as_dict(figures: Figures) -> dict[str, Any]:
    return {**asdict(figures), "own_overhead_share": figures.own_overhead_share}
