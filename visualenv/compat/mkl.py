"""MKL inside torch: its *conditional numerical reproducibility* mode, so that a policy acts alike on every x86-64 CPU.

MKL picks AVX-512, AVX2 or SSE code at run time, and each sums in its own order; in its mode ``COMPATIBLE``
it runs the same code on every CPU (:mod:`visualenv.train.reproducible` says why evaluations need it).
MKL takes its mode once, at its first call in a process.

**The documented way**, used wherever it can work: ``MKL_CBWR=COMPATIBLE`` in the environment, which MKL reads at
its first call (checked with torch 2.13: honoured when set after ``import torch`` and before the first matrix
product, ignored when set after it). visualenv's ``eval`` and ``play`` commands run inside
:func:`compatible_mode`, which sets it before torch loads; the processes they start inherit it.

**MKL's service call** ``mkl_cbwr_set`` stays for one case: evaluation or play run in a process visualenv did not
start (your script, or a training run's own final evaluation). There the variable cannot do the job: it would
stay in the process's environment and reach every process started from it later (training among them, where the
mode costs speed for nothing), and only MKL can say which mode it runs in, which an evaluation's machine record
states. torch exposes no MKL API: it links MKL statically into ``libtorch_cpu.so`` and exports these functions
under MKL's internal names (``mkl_serv_cbwr_get``, ``mkl_serv_cbwr_set``), a detail of each torch build. So the
call is made only on the torch versions in :data:`CHECKED_TORCH`; elsewhere such a process is recorded as not
pinned. ``tests/compat/test_mkl.py`` fails when torch moves.

Checked against torch 2.13.0+cpu (x86-64 Linux wheel).
"""

from __future__ import annotations

import ctypes
import os
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

#: the torch versions (major.minor) whose libtorch_cpu was checked to export MKL's service functions as used here
CHECKED_TORCH = ("2.13",)
#: the environment variable MKL reads its mode from, and the mode
VARIABLE, COMPATIBLE = "MKL_CBWR", "COMPATIBLE"
#: ``mkl_cbwr_get``'s argument for the code branch in force, and the number of the COMPATIBLE branch (mkl_service.h)
BRANCH, COMPATIBLE_BRANCH = 1, 3
#: MKL's internal names of its service functions, as torch's library exports them
GET_SYMBOL, SET_SYMBOL = "mkl_serv_cbwr_get", "mkl_serv_cbwr_set"

_set_before_torch = False


@contextmanager
def compatible_mode() -> Iterator[None]:
    """``MKL_CBWR=COMPATIBLE`` for the block (and the processes started in it), set before torch loads: for the
    processes visualenv starts to evaluate or play. The variable is put back as it was afterwards, so that a
    command run inside another process (a test's) leaves that process's environment alone."""
    global _set_before_torch
    before = os.environ.get(VARIABLE)
    os.environ[VARIABLE] = COMPATIBLE
    _set_before_torch = _set_before_torch or "torch" not in sys.modules
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(VARIABLE, None)
        else:
            os.environ[VARIABLE] = before


def pin() -> bool:
    """MKL in its COMPATIBLE mode where it has not run yet in this process; whether it is in that mode now.

    Call it before a model is built (SB3's orthogonal initialisation already calls MKL). Inside
    :func:`compatible_mode` entered before torch loaded, the variable has done it; elsewhere MKL's service call.
    """
    if _set_before_torch and os.environ.get(VARIABLE) == COMPATIBLE:
        import torch

        return bool(torch.backends.mkl.is_available())
    lib = service()
    if lib is None:
        return False
    if lib.mkl_serv_cbwr_get(BRANCH) == COMPATIBLE_BRANCH:
        return True
    return bool(lib.mkl_serv_cbwr_set(COMPATIBLE_BRANCH) == 0)


def branch() -> int | None:
    """The code branch MKL runs (:data:`COMPATIBLE_BRANCH` when pinned), asked of MKL; None where it cannot be asked."""
    lib = service()
    return None if lib is None else int(lib.mkl_serv_cbwr_get(BRANCH))


def torch_checked() -> bool:
    """Whether the installed torch is one this module was checked against (its MKL symbols are then used)."""
    import torch

    return ".".join(torch.__version__.split("+")[0].split(".")[:2]) in CHECKED_TORCH


def service() -> Any:
    """MKL's service functions inside torch's CPU library, on a checked torch that has them; else None (this loads torch)."""
    try:
        import torch

        if not torch_checked():
            return None
        lib = ctypes.CDLL(str(Path(torch.__file__).parent / "lib" / "libtorch_cpu.so"))
        getattr(lib, GET_SYMBOL).restype = getattr(lib, SET_SYMBOL).restype = ctypes.c_int
        return lib
    except (ImportError, OSError, AttributeError):
        return None
