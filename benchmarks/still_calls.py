"""A batch's render call with nothing moved, repeated: what a profiler should see of tracing and per-pixel work.

    python benchmarks/still_calls.py SPEC N CALLS
    perf record -F 199 --call-graph dwarf python benchmarks/still_calls.py specs/visual_cartpole.yaml 400 6

Builds a batch of N envs, steps it three times, then renders the same binding table CALLS times and prints the
pixels a call and the milliseconds a call. The record: results/benchmarks/render-host-cost-vm.md.
"""

import sys
import time

from visualenv.env.batch import BatchedVectorEnv
from visualenv.render.frames import Frames


def main() -> None:
    spec, envs, calls = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    env = BatchedVectorEnv(spec, envs, autoreset_mode="next_step")
    env.reset(seed=0)
    for _ in range(3):
        env.step(env.action_space.sample())
    renderer = env.renderer
    print("pixels a call", renderer.scene.render.resolution_x * renderer.scene.render.resolution_y, flush=True)
    start = time.perf_counter()
    for _ in range(calls):
        renderer.render(Frames(env.binding_table()))
    print(f"{1000 * (time.perf_counter() - start) / calls:.1f} ms a call", flush=True)
    env.close()


if __name__ == "__main__":
    main()
