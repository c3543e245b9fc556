"""What Blender's render call costs, and what it depends on: pixels, and what moved.

    .venv/bin/python benchmarks/render_floor.py [spec] [renders]

On the spec's built scene (default VisualCartPole-v0), prints the median time of
``bpy.ops.render.render``:

* at several resolutions, with nothing changed between renders: how much of the
  floor is per-pixel path tracing and how much a fixed cost per call;
* after moving one bound object, or only the camera, before each call: what
  Blender's update of a changed scene (depsgraph, Cycles' sync and BVH) adds.

Timings vary from run to run on shared machines; compare within one run.
"""

from __future__ import annotations

import sys
from typing import Any, Callable

import numpy as np

import visualenv
from visualenv.tools.bench import render_call_times


def median_ms(scene_name: str, n: int, before: Callable[[int], None] | None = None) -> float:
    return 1000 * float(np.median(render_call_times(scene_name, n, before)))


def nudge(obj: Any) -> Callable[[int], None]:
    """Move `obj` by a millimetre back and forth: a changed transform, the same picture."""
    x = obj.location[0]

    def move(i: int) -> None:
        obj.location[0] = x + 0.001 * (i % 2)

    return move


def main(spec: str = "VisualCartPole-v0", n: int = 300) -> None:
    env = visualenv.make(spec)
    env.reset(seed=0)
    renderer = env.unwrapped.renderer
    scene = renderer.scene
    name = scene.name
    width, height = scene.render.resolution_x, scene.render.resolution_y
    median_ms(name, 30)  # warm up the persistent session
    print(f"{spec}: bpy.ops.render.render, median of {n} calls")
    for size in (10, 50, 100, 141, 200):
        scene.render.resolution_x = scene.render.resolution_y = size
        median_ms(name, 10)
        print(f"  {f'{size}x{size} ({size * size} pixels), nothing moved':44s} {median_ms(name, n):6.3f} ms")
    scene.render.resolution_x, scene.render.resolution_y = width, height
    median_ms(name, 10)
    base = median_ms(name, n)
    print(f"  {f'{width}x{height}, nothing moved':44s} {base:6.3f} ms")
    movers = [(target.object, renderer.object(target.object)) for target in renderer.plan.bindings if target.property == "location"]
    for label, obj in [*dict(movers).items(), ("camera", scene.camera)]:
        moved = median_ms(name, n, nudge(obj))
        print(f"  {f'{width}x{height}, {label} moved before each call':44s} {moved:6.3f} ms  ({moved - base:+.3f})")
    env.close()


if __name__ == "__main__":
    main(*(sys.argv[1:2] or []), *(int(a) for a in sys.argv[2:3]))
