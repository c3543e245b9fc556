"""Keep the memory a batch's render call frees, so that the next call reuses it rather than faulting it in again.

A batch's render call allocates and frees buffers of tens to hundreds of MB: Blender's render result and Cycles'
render buffers, 16 bytes a pixel and more, for images up to 2048 x 2048. glibc's malloc serves blocks over 32 MB
(its largest mmap threshold) with ``mmap`` and gives them back with ``munmap``, so every call page-faults them in
again and the kernel zeroes every page. Measured (docs/performance.md, *On a GPU*): half of a 4-megapixel call on
an H200 (153 -> 66 ms, system time 12.8 -> 4.2 s of a run) and 12 % of one on the 2-core VM's CPU.

:func:`keep_freed_memory` tells glibc to serve every block from its heap and to keep what is freed at the heap's
top up to 1 GiB: the process's resident memory stays at its peak instead of rising and falling each call. The
setting is the whole process's. A batch whose images reach :data:`LARGE_IMAGE_PIXELS` asks for it; a batch that
closes hands what is free back (:func:`release_freed_memory`), so that making and closing batches in one process
(notebooks, sweeps) does not hold on to each one's peak.
"""

from __future__ import annotations

import ctypes
import platform

#: glibc's ``mallopt`` parameters (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4
#: freed memory at the heap's top kept for reuse, not returned to the system
TRIM_THRESHOLD = 1 << 30
#: the image size from which a batch keeps freed memory: its render result alone is 16 MB, with Cycles' buffers past
#: glibc's 32 MB. Below it glibc already reuses the blocks, and keeping only costs: 16-env batches made and closed
#: 30 times in one process kept 0.17 MB more a round (the heap's top pinned by what each round leaves)
LARGE_IMAGE_PIXELS = 1 << 20

_applied: bool | None = None


def keep_freed_memory() -> bool:
    """No ``mmap`` for large blocks and a 1 GiB trim threshold, once per process; False where the C library is not
    glibc (macOS, musl), which is then left as it is."""
    global _applied
    if _applied is None:
        _applied = False
        if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
            try:
                mallopt = ctypes.CDLL(None).mallopt  # the C library the process runs on
            except (OSError, AttributeError):
                return False
            mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
            _applied = mallopt(M_MMAP_MAX, 0) == 1 and mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
    return _applied


def release_freed_memory() -> None:
    """Return the heap's free memory to the system (``malloc_trim``), where :func:`keep_freed_memory` kept it."""
    if _applied:
        ctypes.CDLL(None).malloc_trim(0)
