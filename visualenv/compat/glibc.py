"""glibc's allocator: one policy for the processes visualenv owns; freed memory handed back when a scene goes.

Checked against glibc 2.36 (Debian 12, x86-64). What is used is glibc's documented interface: ``mallopt``'s
``M_MMAP_MAX`` and ``M_TRIM_THRESHOLD``, ``malloc_trim`` (mallopt(3), malloc_trim(3)) and the matching
``glibc.malloc`` tunables (2.26 and later); it is used on glibc from :data:`OLDEST` on, and on no other C
library (macOS, musl: nothing is done). ``tests/compat/test_glibc.py`` fails when the symbols are gone or the
policy stops doing what it says.

**The policy: freed memory kept.** A batch's render call allocates and frees Blender's render result and
Cycles' render buffers, tens to hundreds of MB. By default glibc serves blocks over its mmap threshold (at
most 32 MB) with ``mmap`` and returns them with ``munmap``, so every call faults every page in again and the
kernel zeroes it. With ``M_MMAP_MAX=0`` every block comes from the heap, and ``M_TRIM_THRESHOLD`` = 1 GiB keeps
up to 1 GiB freed at its top: the process's resident memory stays at its peak instead of rising and falling
each call. Large render calls then spend far less time in the kernel, on a GPU and a CPU alike
(``results/benchmarks/allocator-policy.md``).

The setting is the whole process's, torch's and numpy's blocks included, so it is **opt-in**: visualenv's CLI
commands and the worker processes visualenv starts (vector env and batch workers, RLlib env runners) apply it
(:func:`apply_policy`); making, stepping or closing an env never does. Your own process gets the same with
``GLIBC_TUNABLES`` (:data:`POLICY_TUNABLES`) set when it starts, or by calling :func:`apply_policy`. A process
started with any ``glibc.malloc`` tunable of its own keeps what it was given.
"""

from __future__ import annotations

import ctypes
import functools
import os
from typing import Any

#: the oldest glibc whose ``glibc.malloc`` tunables match the ``mallopt`` parameters used here
OLDEST = (2, 26)
#: ``mallopt``'s parameters (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4
#: freed memory at the heap's top that the policy keeps for reuse
TRIM_THRESHOLD = 1 << 30
#: the policy as glibc reads it from the environment of a process that starts (``GLIBC_TUNABLES=...``)
POLICY_TUNABLES = f"glibc.malloc.mmap_max=0:glibc.malloc.trim_threshold={TRIM_THRESHOLD}"

_applied: bool | None = None


def version() -> tuple[int, int] | None:
    """The glibc this process runs on, as (major, minor); None for another C library."""
    try:
        name, text = os.confstr("CS_GNU_LIBC_VERSION").split()  # type: ignore[union-attr]  # "glibc 2.36": the C library loaded
        major, minor = text.split(".")[:2]
        return (int(major), int(minor)) if name == "glibc" else None
    except (AttributeError, ValueError, OSError):  # not glibc (macOS, musl, Windows)
        return None


class _Mallinfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena",
            "ordblks",
            "smblks",
            "hblks",
            "hblkhd",
            "usmblks",
            "fsmblks",
            "uordblks",
            "fordblks",
            "keepcost",
        )
    ]


@functools.cache
def _glibc() -> Any:
    """The C library this process runs on, where it is a glibc this module was written for; else None."""
    found = version()
    if found is None or found < OLDEST:
        return None
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt.argtypes, libc.mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
        libc.malloc_trim.argtypes, libc.malloc_trim.restype = [ctypes.c_size_t], ctypes.c_int
        if hasattr(libc, "mallinfo2"):  # glibc 2.33 and later
            libc.mallinfo2.restype = _Mallinfo2
    except (OSError, AttributeError):
        return None
    return libc


def available() -> bool:
    """Whether this process runs on a glibc this module was written for, with ``mallopt`` and ``malloc_trim`` there."""
    return _glibc() is not None


def apply_policy() -> bool:
    """Freed memory kept (no ``mmap`` for large blocks, a 1 GiB trim threshold), once per process; whether it is in force.

    For the processes visualenv owns; see the module's docstring. Nothing is done on another C library, or
    where the process was started with ``glibc.malloc`` tunables of its own (then False: theirs are in force).
    """
    global _applied
    if _applied is None:
        libc = _glibc()
        if libc is None or "glibc.malloc." in os.environ.get("GLIBC_TUNABLES", ""):
            _applied = False
        else:
            _applied = libc.mallopt(M_MMAP_MAX, 0) == 1 and libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
    return _applied


def bytes_in_use() -> int | None:
    """Bytes the process holds from ``malloc`` now (``mallinfo2``: heap blocks in use plus mmapped ones); None without it.

    Why not resident memory: what glibc keeps after a ``free`` stays resident, so a freed frame does not show there
    on every machine; this counts what is allocated. glibc 2.33 and later.
    """
    info = getattr(_glibc(), "mallinfo2", None)
    if info is None:
        return None
    found = info()
    return int(found.uordblks + found.hblkhd)


def release_free_memory() -> None:
    """Hand the heaps' free memory back to the system (``malloc_trim``); changes no setting.

    Why: glibc keeps what Blender's render threads free in their arenas, so each env or batch made and closed in
    one process left it larger (``benchmarks/env_rounds.py batch 22``; results/benchmarks/env-rounds-memory.md).
    Called when a renderer removes its scene.
    """
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)


def flush_c_streams() -> None:
    """Flush the C library's stdio buffers (``fflush(NULL)``: Blender's ``printf``), before its descriptors are redirected.

    ``fflush`` is the C standard's: done with any C library the process can name, glibc or not.
    """
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):
        pass
