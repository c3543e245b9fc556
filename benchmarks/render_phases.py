"""Where a batch's render call goes: Cycles' sync, Cycles' tracing and result, and Blender's pipeline around them.

    python benchmarks/render_phases.py [SPEC] [--envs 1024] [--resolution 100] [--steps 10] [--device cpu|gpu]
                                       [--static-instanced]

A render call (``bpy.ops.render.render``) runs the engine's ``update`` (Cycles' session is made or reset) and then
its ``render`` (Cycles syncs the scene, every instance once anything moved; path traces; copies the render buffers
into Blender's result; then the capture's copy). Both methods of Cycles' engine class are timed here; what is left of the call is Blender's pipeline
around them (the depsgraph update of the moved instancers, the render result's buffers). Each figure is the median
per call, for the calls of the measured steps ("moved") and for the same calls again with nothing moved ("still").
Cycles syncs inside the engine's render, so the scene update is what "moved" costs over "still".
``--static-instanced`` keeps static meshes as instances (the path before they were realized), for a before/after.

Two host costs per unit follow: the scene update per instance Cycles syncs (what a moved call costs over a still
one, over the instances and objects the scene draws: every env's instance of each instancer that is not realized,
and the objects copied per env), and the readback per pixel (the capture's copy of the Combined pass inside the
engine's render, and its conversion to the observation's bytes after the call).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

from visualenv.errors import VisualEnvError


def _timed_engine(engine: Any, phases: dict[str, list[float]]) -> None:
    """Time the engine's update and render (Blender passes a registered method as many arguments as it names: explicit
    signatures, not *args)."""
    update, render = engine.update, engine.render

    def timed_update(self: Any, data: Any, depsgraph: Any) -> None:
        start = time.perf_counter()
        update(self, data, depsgraph)
        phases["update"].append(time.perf_counter() - start)

    def timed_render(self: Any, depsgraph: Any) -> None:
        start = time.perf_counter()
        render(self, depsgraph)
        phases["render"].append(time.perf_counter() - start)

    engine.update, engine.render = timed_update, timed_render


def measure(spec: str, envs: int, steps: int, device: str | None) -> dict[str, dict[str, float]]:
    """Median ms per render call of each phase, for moved and still calls."""
    from visualenv.env.batch import BatchedVectorEnv
    from visualenv.render.frames import Frames
    from visualenv.render.profile import Profile
    from visualenv.tools.bench import device_option, timed

    env = BatchedVectorEnv(spec, envs, autoreset_mode="next_step", renderer_options=device_option(device))
    env.reset(seed=0)
    for _ in range(3):  # the first calls build the scene in Cycles and compile the tiles camera
        env.step(env.action_space.sample())
    renderer = env.renderer
    import cycles  # Blender's bundled add-on, importable once bpy is loaded

    from visualenv.render.blender.capture import Capture

    engine = cycles.CyclesRender
    update, render = engine.update, engine.render
    copy_from = Capture._copy_from
    figures = {}
    try:
        for kind in ("moved", "still"):
            phases: dict[str, list[float]] = {"update": [], "render": [], "call": [], "copy": [], "convert": []}
            _timed_engine(engine, phases)
            profile = renderer.profile = Profile()  # the renderer's phases: its render call, the readback
            phases["call"], phases["convert"] = profile.times["render"], profile.times["readback"]
            Capture._copy_from = timed(copy_from, phases["copy"])  # type: ignore[method-assign]
            try:
                for _ in range(steps):
                    if kind == "moved":
                        env.step(env.action_space.sample())
                    else:
                        renderer.render(Frames(env.binding_table()))  # the same tiles again: nothing moved
            finally:
                engine.update, engine.render = update, render
                Capture._copy_from = copy_from  # type: ignore[method-assign]
                renderer.profile = None
            median = {name: 1000 * statistics.median(values) for name, values in phases.items()}
            median["around"] = median["call"] - median["update"] - median["render"]
            median["calls per step"] = len(phases["call"]) / steps
            figures[kind] = median
        figures["drawn"] = {"instances": drawn_instances(renderer), "pixels": renderer.scene.render.resolution_x
                            * renderer.scene.render.resolution_y}
    finally:
        env.close()
    return figures


def drawn_instances(renderer: Any) -> int:
    """What Cycles syncs object by object once anything moves: each env's instance of every instancer not realized
    into one static mesh, and every object of the copies (their anchors and lights, and cameras left as copies)."""
    instancers = renderer._instances._instancers if renderer._instances is not None else []
    # copy 0's anchor also holds the originals its instancers draw, hidden: not synced
    copied = sum(sum(o.as_pointer() not in renderer._removed for o in copy.anchor.children_recursive) + 1
                 for copy in renderer._copies if copy.anchor is not None)
    return renderer.n * sum(not inst.realized for inst in instancers) + copied


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("spec", nargs="?", default="specs/visual_cartpole.yaml")
    parser.add_argument("--envs", type=int, default=1024)
    parser.add_argument("--resolution", type=int, default=100)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--device", choices=("cpu", "gpu"), default=None)
    parser.add_argument("--static-instanced", action="store_true", help="keep static meshes as instances (not realized)")
    args = parser.parse_args()
    if args.static_instanced:
        from visualenv.render.blender.batch import instance_nodes

        instance_nodes.REALIZED_TRIANGLES = 0
    data = yaml.safe_load(Path(args.spec).read_text())
    data["observation"]["resolution"] = [args.resolution, args.resolution]
    with tempfile.TemporaryDirectory() as folder:
        spec = Path(folder) / Path(args.spec).name
        spec.write_text(yaml.safe_dump(data, sort_keys=False))
        try:
            figures = measure(str(spec), args.envs, args.steps, args.device)
        except VisualEnvError as exc:  # e.g. a resolution the spec's checks refuse
            sys.exit(f"{args.spec} at {args.resolution}x{args.resolution}: {exc}")
    static = "instanced" if args.static_instanced else "realized"
    print(f"{args.spec} at {args.resolution}x{args.resolution}, {args.envs} envs, device {args.device or 'of the spec'}, "
          f"static meshes {static}; ms per render call (medians)")
    print(f"  {'':>6} {'call':>8} {'engine.update':>14} {'engine.render':>14} {'around':>8} {'calls/step':>11}")
    for kind in ("moved", "still"):
        m = figures[kind]
        print(f"  {kind:>6} {m['call']:>8.1f} {m['update']:>14.1f} {m['render']:>14.1f} {m['around']:>8.1f} {m['calls per step']:>11.1f}")
    moved, still, drawn = figures["moved"], figures["still"], figures["drawn"]
    instances, pixels = drawn["instances"], drawn["pixels"]
    update_us = 1000 * (moved["call"] - still["call"]) / instances
    print(f"  scene update: {moved['call'] - still['call']:.1f} ms a call over {instances:,} instances and objects synced: "
          f"{update_us:.2f} us each")
    copy_ns, convert_ns = (1e6 * still[name] / pixels for name in ("copy", "convert"))
    print(f"  readback: {pixels:,} pixels a call; the pass copied {still['copy']:.2f} ms ({copy_ns:.2f} ns a pixel), "
          f"converted {still['convert']:.2f} ms ({convert_ns:.2f} ns a pixel); {copy_ns + convert_ns:.2f} ns a pixel in all")


if __name__ == "__main__":
    main()
