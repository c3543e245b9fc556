"""Per-render overhead of BlenderRenderer: render(Frames) vs Blender's raw render call.

    .venv/bin/python benchmarks/blender_render_overhead.py [spec] [n]

Renders the spec's observation n times with changing binding values (as env.step
does), then the bare ``bpy.ops.render.render`` call on the same scene, and prints
milliseconds per call and the difference (binding writes + readback + conversion).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from visualenv.env import VisualEnv
from visualenv.render.pixels import read_bmp, to_grayscale
from visualenv.render.frames import Frames


def main(spec: str = "specs/visual_cartpole.yaml", n: int = 200) -> None:
    env = VisualEnv(spec)
    env.reset(seed=0)
    renderer = env.renderer
    values = [env.binding_values()]
    for i in range(n - 1):
        env.step(i % 2)
        values.append(env.binding_values())
        if env._done if hasattr(env, "_done") else False:
            env.reset()
    for v in values[:10]:  # warm up
        renderer.render(Frames((v,)))

    def timed(fn) -> float:
        best = []
        for _ in range(3):
            t = time.perf_counter()
            fn()
            best.append((time.perf_counter() - t) / n * 1000)
        return min(best)

    obs = timed(lambda: [renderer.render(Frames((v,))) for v in values])
    raw = timed(lambda: [renderer.raw_render() for _ in range(n)])
    moved = timed(lambda: [(renderer.apply(v), renderer.raw_render()) for v in values])
    apply_ms = timed(lambda: [renderer.apply(v) for v in values])
    read_ms = timed(lambda: [read_bmp(renderer._output.path) for _ in range(n)])
    image = read_bmp(renderer._output.path)
    gray_ms = timed(lambda: [to_grayscale(image) for _ in range(n)])
    shape = np.asarray(renderer.render(Frames((values[0],)))[0]).shape
    print(f"spec {spec}, observation {shape}, {n} renders, best of 3")
    print(f"render(Frames): {obs:.3f} ms/call")
    print(f"raw bpy.ops.render.render(write_still=True): {raw:.3f} ms/call")
    print(f"raw render of a scene whose objects moved (apply + render call): {moved:.3f} ms/call")
    print(f"overhead vs the unchanged-scene render: {obs - raw:.3f} ms/call ({(obs - raw) / obs * 100:.1f}%)")
    print(f"overhead vs the moved-scene render: {obs - moved:.3f} ms/call ({(obs - moved) / obs * 100:.1f}%)")
    print(f"  parts: apply bindings {apply_ms:.3f} ms, BMP read {read_ms:.3f} ms, grayscale {gray_ms:.3f} ms")
    env.close()


if __name__ == "__main__":
    main(*(sys.argv[1:2] or []), *(int(a) for a in sys.argv[2:3]))
