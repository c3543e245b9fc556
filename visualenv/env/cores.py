"""Which cores each worker may use: disjoint shares by default, and confining a process to its share.

Worker shares follow this process's affinity mask (:func:`usable_cores`), which a container,
a batch scheduler or ``taskset`` may make smaller than the machine.

Why confine: Blender sizes its thread pools (scene evaluation, not only rendering) to the cores
it may run on when it starts, so unconfined workers past half a machine's cores each start pools
for every core and together run slower than half as many (results/benchmarks/parallel-workers.md).
So n workers on c cores each get their own c/n cores (one core each, round
robin, when n > c), are confined to them before Blender starts, and render with that many threads.
``pin=False`` (``--no-pin``) turns it off, for a machine shared with other jobs that pin themselves.
RLlib's runners, which Ray places itself, each claim a free core of their node (:func:`claim_core`).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import IO

Share = tuple[int, ...]
_claimed: list[IO[bytes]] = []  # the open lock files of the cores this process claimed: held until it exits


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


def worker_cores(n: int, pin: bool = True) -> list[Share | None]:
    """Each of `n` workers' own cores: disjoint slices of this process's cores (sizes differing by at most one),
    or one core each, round robin, when n exceeds them. None: not confined (`pin` off, one worker, or one core)."""
    if not pin or n < 2 or not hasattr(os, "sched_setaffinity"):
        return [None] * n
    cores = usable_cores()
    c = len(cores)
    if c < 2:
        return [None] * n
    if n >= c:
        return [(cores[i % c],) for i in range(n)]
    bounds = [i * c // n for i in range(n + 1)]
    return [tuple(cores[bounds[i] : bounds[i + 1]]) for i in range(n)]


def render_threads(share: Share | None, n: int, threads: int | None = None) -> int:
    """A worker's render threads: `threads` if given, else the size of its share (confined), else its part of the cores."""
    return threads or (len(share) if share else default_threads(n))


def confine(cores: Iterable[int]) -> None:
    """Confine every thread of this process to `cores` (threads started later inherit it); call it before Blender starts."""
    allowed = set(cores)
    try:
        threads = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]
    for tid in threads:
        with contextlib.suppress(OSError):
            os.sched_setaffinity(tid, allowed)


def claim_core() -> int | None:
    """Claim a core of this machine no other visualenv process has claimed, and confine this process to it.

    For workers placed by someone else (Ray's EnvRunners): a lock file per core, held while the process
    lives. None, and nothing confined, when every usable core is taken or locks are unavailable.
    """
    if _claimed or not hasattr(os, "sched_setaffinity"):
        return None
    try:
        import fcntl
    except ImportError:  # not on a POSIX system
        return None
    folder = Path(tempfile.gettempdir()) / f"visualenv-cores-{os.getuid()}"
    with contextlib.suppress(OSError):
        folder.mkdir(exist_ok=True)
    for core in usable_cores():
        try:
            handle = (folder / f"{core}.lock").open("wb")
        except OSError:
            return None
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _claimed.append(handle)
        confine([core])
        return core
    return None
