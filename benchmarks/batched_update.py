"""A batch's scene update per step: copied objects, instances, and instances with static meshes realized (the default).

    python benchmarks/batched_update.py [SPEC] [--envs 1024] [--resolution 8] [--steps 20] [--rounds 2]
                                        [--paths copies,instanced,realized]

#38 asks for <= 15 ms at N = 1,024 of VisualCartPole on 2 cores.

The observation is shrunk to RESOLUTION x RESOLUTION so that tracing does not
hide the update. Each round measures every chosen path, each in a fresh process,
alternated (the machine is shared: compare figures of one run). The scene
update is the writes into the scene (Python) plus the render call minus the
same call with nothing moved (Blender's depsgraph and Cycles' sync). The paths: ``copies`` (every object copied per
env), ``instanced`` (every mesh an instance, static ones too: the path before static meshes were realized),
``realized`` (what batches do: moving meshes instanced, static ones realized into one mesh).
"""

import argparse
import multiprocessing
import tempfile
from pathlib import Path

import yaml

from visualenv.tools.bench_batch import measure_batch


PATHS = ("copies", "instanced", "realized")


def _run(spec: str, n: int, steps: int, path: str, queue: "multiprocessing.Queue[dict]") -> None:
    if path == "instanced":
        from visualenv.render.blender.batch import instance_nodes

        instance_nodes.REALIZED_TRIANGLES = 0  # no static mesh is small enough to realize: every mesh stays an instance
    queue.put(measure_batch(spec, n, steps, instanced=path != "copies"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("spec", nargs="?", default="specs/visual_cartpole.yaml")
    parser.add_argument("--envs", type=int, default=1024)
    parser.add_argument("--resolution", type=int, default=8)
    parser.add_argument("--steps", type=int, default=20, help="measured steps of all envs")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--paths", default=",".join(PATHS), help="comma-separated, of " + ", ".join(PATHS))
    args = parser.parse_args()
    paths = args.paths.split(",")
    if not set(paths) <= set(PATHS):
        parser.error(f"--paths: choose among {', '.join(PATHS)}")
    data = yaml.safe_load(Path(args.spec).read_text())
    data["observation"]["resolution"] = [args.resolution, args.resolution]
    context = multiprocessing.get_context("spawn")
    with tempfile.TemporaryDirectory() as folder:
        spec = Path(folder) / Path(args.spec).name
        spec.write_text(yaml.safe_dump(data, sort_keys=False))
        print(f"{args.spec} at {args.resolution}x{args.resolution}, {args.envs} envs, {args.steps} steps; ms per step of all envs (medians)")
        print(f"  {'path':>9} {'write':>7} {'render-still':>13} {'scene update':>13} {'render':>8} {'step':>8} {'env-steps/s':>12} {'RSS MB':>7} {'build s':>8}")
        for _ in range(args.rounds):
            for path in paths:
                queue = context.Queue()
                child = context.Process(target=_run, args=(str(spec), args.envs, args.steps, path, queue))
                child.start()
                r = queue.get()
                child.join()
                update = r["write_ms"] + r["scene_update_ms"]
                print(f"  {path:>9} {r['write_ms']:>7.2f} {r['scene_update_ms']:>13.1f} {update:>13.1f} "
                      f"{r['render_ms']:>8.1f} {r['step_ms']:>8.1f} {r['steps_per_s']:>12.0f} {r['rss_mb']:>7.0f} {r['build_s']:>8.1f}", flush=True)


if __name__ == "__main__":
    main()
