"""How many steps/s one core can render, and so what N parallel workers can reach at best.

    .venv/bin/python benchmarks/parallel_ceiling.py [SPEC] [STEPS]

Each case runs in a fresh process (a pinned process must be pinned before
Blender starts its thread pools) and prints steps/s and the cores the process
and its children kept busy. Cases: one env on every core; one env with one
render thread; the same pinned to one core; N workers (one render thread each),
unpinned and pinned. A core's pinned rate times the number of cores, over the
single-env rate, is the best speed-up workers can give on this machine.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import time

from visualenv.env.cores import usable_cores

CASES = ("single", "single:1", "single:1:pin", "vec", "vec:pin")


def _cpu_seconds() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def run_single(spec: str, steps: int, threads: int | None, pin: bool) -> tuple[float, float]:
    if pin:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    import visualenv
    from visualenv.tools.bench import random_actions, run_env

    env = visualenv.make(spec, **({"threads": threads} if threads else {}))
    actions = random_actions(env, 50 + steps, seed=0)
    run_env(env, actions[:50], seed=0)  # warm-up
    cpu, started = _cpu_seconds(), time.perf_counter()
    run_env(env, actions[50:], seed=1)
    seconds = time.perf_counter() - started
    env.close()
    return steps / seconds, (_cpu_seconds() - cpu) / seconds


def run_vec(spec: str, steps: int, workers: int, pin: bool) -> tuple[float, float]:
    import psutil

    from visualenv.env.vector import make_vec

    vec = make_vec(spec, workers, threads=1, pin=pin)
    vec.reset(seed=0)
    vec.action_space.seed(0)
    for _ in range(50):
        vec.step(vec.action_space.sample())
    processes = [psutil.Process(p.pid) for p in vec.processes]

    def cpu() -> float:
        return _cpu_seconds() + sum(sum(p.cpu_times()[:2]) for p in processes)

    used, started = cpu(), time.perf_counter()
    for _ in range(steps // workers):
        vec.step(vec.action_space.sample())
    seconds = time.perf_counter() - started
    used = cpu() - used
    vec.close()
    return steps / seconds, used / seconds


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--case":  # one case, in its own process
        _, _, case, spec, steps = sys.argv
        kind, *rest = case.split(":")
        pin = "pin" in rest
        if kind == "single":
            threads = int(rest[0]) if rest and rest[0] != "pin" else None
            rate, cores = run_single(spec, int(steps), threads, pin)
        else:
            rate, cores = run_vec(spec, int(steps), len(usable_cores()), pin)
        print(f"{rate:.1f} {cores:.2f}")
        return
    spec = sys.argv[1] if len(sys.argv) > 1 else "VisualCartPole-v0"
    steps = sys.argv[2] if len(sys.argv) > 2 else "2000"
    cores = len(usable_cores())
    print(f"{spec}, {steps} steps per case, {cores} cores (vec: {cores} workers, one render thread each)")
    rates = {}
    for case in CASES:
        out = subprocess.run([sys.executable, __file__, "--case", case, spec, steps], capture_output=True, text=True, check=True)
        rate, used = (float(x) for x in out.stdout.split()[-2:])
        rates[case] = rate
        print(f"  {case:14s} {rate:8.1f} steps/s  {used:5.2f} cores busy")
    ceiling = rates["single:1:pin"] * cores / rates["single"]
    print(f"  best possible speed-up of {cores} workers: {ceiling:.2f}x (one pinned core's rate x {cores} / one env)")


if __name__ == "__main__":
    main()
