"""The DMC tasks' step rates: state-only control steps/s (beside dm_control's own), and rendered steps/s at 84x84.

    python benchmarks/dmc_step_rates.py [--state-steps 2000] [--rendered-steps 60] [IDS...]

For each id: the state-only env (``render=False, action_repeat=1``) and dm_control's task
(``suite.load``, when dm_control is installed) each take ``--state-steps`` control steps of the same
seeded random actions (episodes end at 1,000 and reset, outside the timing); then the rendered env
(84x84 RGB through camera 0, its default action repeat, one render a step) takes ``--rendered-steps``
steps after a reset and 5 untimed steps (the first renders compile Cycles' kernels and build the
scene). Rendered rates are agent steps/s and control steps/s (times the action repeat). Prints one
Markdown table row per id; the load average is printed first (the 2-core VM is shared).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import visualenv

#: id -> dm_control's domain and task
TASKS = {
    "DMC-cartpole-swingup-v0": ("cartpole", "swingup"),
    "DMC-reacher-easy-v0": ("reacher", "easy"),
    "DMC-cheetah-run-v0": ("cheetah", "run"),
    "DMC-finger-spin-v0": ("finger", "spin"),
    "DMC-ball_in_cup-catch-v0": ("ball_in_cup", "catch"),
    "DMC-walker-walk-v0": ("walker", "walk"),
}


def state_rate(ident: str, steps: int) -> float:
    """Control steps per second of the state-only env, action_repeat=1 (resets at episode ends, untimed)."""
    env = visualenv.make(ident, render=False, action_repeat=1)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, size=(steps, *env.action_space.shape))
    spent = 0.0
    for action in actions:
        start = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(action)
        spent += time.perf_counter() - start
        if terminated or truncated:
            env.reset()
    env.close()
    return steps / spent


def dm_control_rate(ident: str, steps: int) -> float | None:
    """Control steps per second of dm_control's own task (None without dm_control)."""
    os.environ.setdefault("MUJOCO_GL", "disable")
    try:
        from dm_control import suite
    except ImportError:
        return None
    env = suite.load(*TASKS[ident], task_kwargs={"random": 0})
    env.reset()
    actions = np.random.default_rng(0).uniform(-1, 1, size=(steps, *env.action_spec().shape))
    spent = 0.0
    for action in actions:
        start = time.perf_counter()
        time_step = env.step(action)
        spent += time.perf_counter() - start
        if time_step.last():
            env.reset()
    return steps / spent


def rendered_rate(ident: str, steps: int) -> tuple[float, int]:
    """Agent steps per second of the rendered env (84x84 RGB, its default action repeat), and that repeat."""
    env = visualenv.make(ident)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        env.step(rng.uniform(-1, 1, size=env.action_space.shape))
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, size=env.action_space.shape))
        if terminated or truncated:
            env.reset()
    rate = steps / (time.perf_counter() - start)
    repeat = env.unwrapped.action_repeat
    env.close()
    return rate, repeat


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("ids", nargs="*", default=list(TASKS))
    parser.add_argument("--state-steps", type=int, default=2000)
    parser.add_argument("--rendered-steps", type=int, default=60)
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()}")
    print("| id | state-only control steps/s | dm_control's control steps/s | rendered steps/s (84x84 RGB) | action repeat | rendered control steps/s |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for ident in args.ids:
        ours = state_rate(ident, args.state_steps)
        theirs = dm_control_rate(ident, args.state_steps)
        rendered, repeat = rendered_rate(ident, args.rendered_steps)
        shown = f"{theirs:,.0f}" if theirs is not None else "-"
        print(f"| `{ident}` | {ours:,.0f} | {shown} | {rendered:.1f} | {repeat} | {rendered * repeat:.0f} |", flush=True)
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
