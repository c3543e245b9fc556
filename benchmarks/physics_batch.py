"""A batch of physics envs: the share of a batch step that MuJoCo's stepping and the pose writing take, and memory per env.

    python benchmarks/physics_batch.py [--spec SPEC] [--envs 256] [--steps 40] [--resolution 8] [--mode state|rendered|both]
                                       [--copies] [--spec-camera] [--engine mujoco|lanes|both]
    python benchmarks/physics_batch.py --kernels     # N MjData stepped: a Python loop, a thread pool, the batch, mujoco.rollout

"physics" is the time in MuJoCo's stepping (the controls written, frame_skip ``mj_step``,
``mj_rnePostConstraint``, the blow-up check, the copies the reads take), whether a batch steps each
lane's MjData from its own generated step or all of them in one call, by MuJoCo's batch API
(``--engine mujoco``, where the installed mujoco has ``mujoco.batch``) or each lane's MjData on a
thread pool (``--engine lanes``, the path before it; ``both`` alternates them, lanes first, in one
process); "poses" is the time writing every env's MuJoCo
poses into the scene: into each env's copy of the model's objects, and, where the bodies are drawn
as instances, composing and writing every instancer's transforms (the whole of ``InstancedCopies.write``,
the spec's own instanced objects included). Both are timed by wrapping the functions that do
them, around a batch stepped with random actions (seeded). Memory per env is the growth of the
process's RSS from before the batch is made to after its steps, divided by N: an upper bound, as
it includes what the batch builds once (the Blender scene).

``--copies`` renders with every object copied per env, its poses written copy by copy (the path
before the model's bodies were instanced: before/after figures). ``--spec-camera`` replaces an
observation camera of the model that moves (HalfCheetah's ``track``, which a batch refuses) by a
fixed camera of the spec's own, from the side.
"""

from __future__ import annotations

import argparse
import os
import re
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


class Timer:
    """Accumulated seconds of the wrapped calls."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.on = False

    def wrap(self, func: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            if not self.on:
                return func(*args, **kwargs)
            start = time.perf_counter()
            try:
                return func(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start
        return timed


def instrument(physics: Timer, poses: Timer) -> None:
    """Wrap the stepping (per lane and batched, where the code has it) and the pose writing."""
    from visualenv.env import batch as batched
    from visualenv.physics import simulation

    stepper = simulation.Simulation.stepper

    def timed_stepper(self: Any, controls: Any, *moved: Any) -> Any:
        return physics.wrap(stepper(self, controls, *moved))

    simulation.Simulation.stepper = timed_stepper  # type: ignore[method-assign]
    try:
        from visualenv.physics import batch  # the batched stepping, where this version of the code has it
    except ImportError:
        batch = None
    if batch is not None:
        batch.BatchSimulation.advance = physics.wrap(batch.BatchSimulation.advance)  # type: ignore[method-assign]
    # the poses handed to the renderer: _frames gathers them with the binding table (_pose_copies before the Frames API)
    posing = "_pose_copies" if hasattr(batched.BatchedVectorEnv, "_pose_copies") else "_frames"
    setattr(batched.BatchedVectorEnv, posing, poses.wrap(getattr(batched.BatchedVectorEnv, posing)))
    try:
        from visualenv.render.blender.batch import instances  # the instanced bodies' poses, where this version of the code has them
    except ImportError:
        return
    instances.InstancedCopies.write = poses.wrap(instances.InstancedCopies.write)  # type: ignore[method-assign]


#: --spec-camera: a fixed camera from the side, for a spec whose observation camera is the model's moving one
SIDE_CAMERA = "scene:\n  objects:\n    BenchSide: {camera: perspective, location: [0, -4, 0.6], rotation: [1.5708, 0, 0], lens: 30}\n"


def spec_at(resolution: int, spec: Path, folder: str, spec_camera: bool = False) -> Path:
    """A copy of the spec whose observation is resolution x resolution (its model, named relative to the spec, made absolute)."""
    text = spec.read_text(encoding="utf-8")
    text = re.sub(r"^(  model: )(?!package:)(\S+)$", lambda m: m.group(1) + str((spec.parent / m.group(2)).resolve()), text, flags=re.M)
    text = re.sub(r"resolution: \[\d+, \d+\]", f"resolution: [{resolution}, {resolution}]", text)
    if spec_camera:
        if re.search(r"^scene:", text, re.M):
            raise SystemExit("--spec-camera: the spec has a scene section of its own; give it a camera there")
        text = re.sub(r"observation: \{camera: \w+", "observation: {camera: BenchSide", text) + SIDE_CAMERA
    out = Path(folder) / spec.name
    out.write_text(text, encoding="utf-8")
    return out


def use_engine(engine: str) -> None:
    """Step batches by MuJoCo's batch API ("mujoco", where this code and mujoco have it) or each lane's MjData ("lanes")."""
    try:
        from visualenv.physics import batch, batch_mujoco as mujoco_batch
    except ImportError:  # code before the batch API: always the lanes
        return
    batch.batch_module = mujoco_batch.batch_module if engine == "mujoco" else (lambda *args: None)  # type: ignore[assignment]


def measure(spec: Path, n: int, steps: int, rendered: bool, copies: bool = False) -> None:
    from visualenv.env.batch import BatchedVectorEnv

    physics, poses = Timer(), Timer()
    instrument(physics, poses)
    before = rss_mb()
    copied = {"backend": "visualenv.tools.bench_batch:copied_renderer"} if rendered and copies else {}
    env = BatchedVectorEnv(spec, n, render=rendered, **copied)  # copies: every object copied, no instances
    engine = "mujoco.batch" if getattr(env._physics, "engine", None) is not None else "lanes"
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    space = env.action_space

    def action() -> Any:
        if hasattr(space, "nvec"):
            return rng.integers(0, space.nvec)
        return rng.uniform(np.maximum(space.low, -1), np.minimum(space.high, 1)).astype(space.dtype)

    for _ in range(3):  # warm-up: the first render builds and compiles the scene
        env.step(action())
    physics.on = poses.on = True
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        env.step(action())
    total, cpu = time.perf_counter() - start, time.process_time() - cpu
    after = rss_mb()
    env.close()
    step_ms = total / steps * 1e3
    phys_ms, pose_ms = physics.seconds / steps * 1e3, poses.seconds / steps * 1e3
    share = (phys_ms + pose_ms) / step_ms * 100
    kind = ("rendered, copies" if copies else "rendered") if rendered else "state-only"
    print(f"{spec.name} {kind}, {engine}, N={n}: batch step {step_ms:.2f} ms ({n / total * steps:.0f} env-steps/s); physics {phys_ms:.2f} ms, "
          f"poses {pose_ms:.2f} ms: {share:.1f} % of the step; process CPU {cpu / steps * 1e3:.0f} ms a step; RSS +{after - before:.0f} MB = {(after - before) / n:.2f} MB/env", flush=True)


def kernels(spec: Path, sizes: list[int], seconds: float) -> None:
    """N lanes' MjData stepped frame_skip times, three ways, on the spec's model (the same work, whatever does it)."""
    from visualenv.compiler.program import compile_spec
    from visualenv.spec.loader import load_spec

    plan = compile_spec(load_spec(spec)).physics
    assert plan is not None, f"{spec} has no physics section"
    for n in sizes:
        kernel(spec.name, plan, n, seconds)


def kernel(label: str, plan: Any, n: int, seconds: float) -> None:
    from concurrent.futures import ThreadPoolExecutor

    import mujoco
    from mujoco import rollout

    fs, cores = plan.frame_skip, len(os.sched_getaffinity(0))
    sims = [plan.simulation() for _ in range(n)]
    for s in sims:
        mujoco.mj_forward(s.model, s.data)
    pairs = [(s.model, s.data) for s in sims]
    step, post = mujoco.mj_step, mujoco.mj_rnePostConstraint

    def run(chunk: list) -> None:
        for m, d in chunk:
            step(m, d, nstep=fs)
            post(m, d)

    pool = ThreadPoolExecutor(cores)
    chunks = [pairs[i::cores] for i in range(cores)]
    model = sims[0].model
    nstate = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    start_state = np.zeros((n, nstate))
    control = np.zeros((n, fs, model.nu))
    states, sensors = np.empty((n, fs, nstate)), np.empty((n, fs, model.nsensordata))
    roller = rollout.Rollout(nthread=cores)
    scratch = [mujoco.MjData(model) for _ in range(cores)]
    models = [s.model for s in sims]
    use_engine("mujoco")
    batch = plan.batch(sims, workers=cores)
    use_engine("lanes")
    lanes = plan.batch([plan.simulation() for _ in range(n)], workers=cores)
    zeros = [np.zeros(n) for _ in plan.controls]
    ways = {
        "python loop": lambda: run(pairs),
        f"{cores} threads": lambda: list(pool.map(run, chunks)),
        f"BatchSimulation.advance, lanes ({cores} threads)": lambda: lanes.advance(zeros),
        f"BatchSimulation.advance, {'mujoco.batch' if getattr(batch, 'engine', None) else 'lanes'} ({cores} threads)":
            lambda: batch.advance(zeros),
        f"rollout ({cores} threads)": lambda: roller.rollout(models, scratch, start_state, control, nstep=fs,
                                                              state=states, sensordata=sensors, skip_checks=True),
    }
    for name, way in ways.items():
        way()
        count, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds:
            way()
            count += 1
        print(f"{label} N={n} {name}: {(time.perf_counter() - start) / count * 1e3:.3f} ms a batch step", flush=True)
    pool.shutdown()
    roller.close()
    batch.close()
    lanes.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spec", type=Path, default=ROOT / "specs" / "mujoco" / "inverted_pendulum.yaml")
    parser.add_argument("--envs", type=int, default=256)
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--resolution", type=int, default=8, help="the rendered batch's observation size (square)")
    parser.add_argument("--mode", choices=("state", "rendered", "both"), default="both")
    parser.add_argument("--kernels", action="store_true", help="only compare ways of stepping N MjData (N = 16, 64, 256)")
    parser.add_argument("--copies", action="store_true", help="rendered: copy every object per env (the path before instanced bodies)")
    parser.add_argument("--spec-camera", action="store_true", help="observe through a fixed camera of the spec's own (for a moving model camera)")
    parser.add_argument("--engine", choices=("mujoco", "lanes", "both"), default="mujoco",
                        help="step by MuJoCo's batch API, each lane's MjData (the path before it), or both, alternated")
    args = parser.parse_args()
    if args.kernels:
        kernels(args.spec, [16, 64, 256], 1.0)
        return
    engines = ("lanes", "mujoco") if args.engine == "both" else (args.engine,)
    with tempfile.TemporaryDirectory() as folder:
        spec = spec_at(args.resolution, args.spec, folder, args.spec_camera)
        for rendered in {"state": (False,), "rendered": (True,), "both": (False, True)}[args.mode]:
            for engine in engines:
                use_engine(engine)
                measure(spec, args.envs, args.steps, rendered=rendered, copies=args.copies)


if __name__ == "__main__":
    main()
