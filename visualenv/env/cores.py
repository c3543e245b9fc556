"""Which cores a worker may use, and pinning a worker to one.

Worker render threads follow this process's affinity mask (:func:`usable_cores`),
which a container, a batch scheduler or ``taskset`` may make smaller than the machine.

``pin=True`` pins worker i to core i (round robin over the cores this process
may use). A Blender render keeps more threads busy than its render threads: with
one render thread, Cycles' session thread traces while an idle thread of
Blender's pool spins on the other core. Pinning keeps that spinning off another
worker's core, which steadies the workers' render times more than it raises
steps/s (``visualenv bench --workers N --pin`` and ``benchmarks/parallel_ceiling.py``
measure it; docs/performance.md has the figures), and pinning would crowd two
jobs onto the same cores, so it is off by default.
"""

from __future__ import annotations

import contextlib
import os


def usable_cores() -> list[int]:
    """The cores this process may run on: its affinity mask, which a container, a batch
    scheduler or ``taskset`` may make smaller than the machine (``os.cpu_count()``)."""
    try:
        return sorted(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return list(range(os.cpu_count() or 1))


def default_threads(n_envs: int) -> int:
    """Render threads per worker that fill this process's cores without oversubscribing them."""
    return max(1, len(usable_cores()) // max(1, n_envs))


def worker_cores(n: int, pin: bool = True) -> list[int | None]:
    """The core each of `n` workers is pinned to: round robin over this process's cores (None: not pinned)."""
    if not pin or n < 2 or not hasattr(os, "sched_setaffinity"):
        return [None] * n
    cores = usable_cores()
    if len(cores) < 2:
        return [None] * n
    return [cores[i % len(cores)] for i in range(n)]


def pin_to_core(core: int) -> None:
    """Pin every thread of this process to `core` (threads started later inherit it)."""
    try:
        threads = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]
    for tid in threads:
        with contextlib.suppress(OSError):
            os.sched_setaffinity(tid, {core})
