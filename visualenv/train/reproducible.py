"""Policy inference that gives the same actions on any x86-64 CPU, and a record of the machine an evaluation ran on.

A policy's float arithmetic follows the CPU's vector instructions: oneDNN (torch's
convolutions) and MKL (its matrix products) pick AVX-512, AVX2 or SSE code at run
time, and each sums in its own order. Discrete agents hide the last-digit
differences behind argmax; continuous ones act on them, and over an episode they
grow (LunarLanding's first episode, AVX2 against AVX-512:
results/benchmarks/cross-machine-replay.md). So evaluations and play run the policy with oneDNN off (torch's own
convolution, whose products go through MKL) and MKL in its *conditional numerical
reproducibility* mode ``COMPATIBLE``, which runs the same code on every CPU.
Checked on the development machine: the same returns, to the last bit, under
``ONEDNN_MAX_CPU_ISA=SSE41`` and ``ATEN_CPU_CAPABILITY=default``.

MKL takes its mode once, before its first call in a process: a process that
already trained (a run's own final evaluation) cannot be pinned afterwards, and
its record says so. ``visualenv eval`` and ``play`` set ``MKL_CBWR=COMPATIBLE``
before torch loads, so they are always pinned (:mod:`visualenv.compat.mkl`, which also pins
a process visualenv did not start).

What pinning cannot reach is the renderer: Cycles and Embree pick their kernels
by CPU too. :func:`machine_record` notes what an evaluation ran on, and
:func:`unlike` says how another machine differs, so a replay elsewhere is
compared with a tolerance (:mod:`visualenv.train.evaluation`) instead of bit for bit.
"""

from __future__ import annotations

import platform
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

from visualenv.compat import mkl
from visualenv.versions import versions

#: the keys of a machine record that must agree for a replay to be exact
LIKENESS_KEYS = ("cpu_isa", "cpu_features", "torch", "blender", "numpy", "mujoco", "pinned")
#: the CPU flags of vector instructions: libraries pick their code by them (two AVX-512 Xeons, Cascade Lake and Emerald
#: Rapids, rendered Goalie's and the pendulum's same states in other last bits), so machines alike replay bit for bit
VECTOR_FLAG_PREFIXES = (
    "sse",
    "ssse",
    "avx",
    "fma",
    "f16c",
    "amx",
    "vaes",
    "vpclmulqdq",
    "gfni",
    "sha_ni",
    "bmi",
    "adx",
)


@contextmanager
def pinned_inference() -> Iterator[bool]:
    """Torch on one thread, oneDNN off and MKL pinned while a policy acts; yields whether MKL could be pinned.

    One thread: a forward pass on one observation gains nothing from more, and beside
    Blender or another run each parallel region waits for a busy core, which made a step
    many times slower (results/benchmarks/code-choices.md). Torch is
    left alone if nothing imported it (random actions).
    """
    torch = sys.modules.get("torch")
    if torch is None:
        yield False
        return
    threads, onednn = torch.get_num_threads(), torch.backends.mkldnn.enabled
    torch.set_num_threads(1)
    torch.backends.mkldnn.enabled = False
    try:
        yield mkl.pin()
    finally:
        torch.set_num_threads(threads)
        torch.backends.mkldnn.enabled = onednn


def machine_record(pinned: bool) -> dict[str, Any]:
    """What a replay of an evaluation needs to know about the machine that ran it."""
    record: dict[str, Any] = {
        "cpu_isa": cpu_isa(),
        "cpu_features": cpu_features(),
        "cpu": _cpu_name(),
        "machine": platform.machine(),
        "pinned": pinned,
    }
    torch = sys.modules.get("torch")
    record["torch"] = torch.__version__ if torch is not None else None
    known = versions()
    record["blender"], record["numpy"], record["mujoco"] = known.get("blender"), known["numpy"], known.get("mujoco")
    return record


def _cpu_flags() -> set[str]:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def cpu_features() -> str:
    """This CPU's vector instruction flags, sorted (:data:`VECTOR_FLAG_PREFIXES`): what "a like machine" must share."""
    return " ".join(sorted(f for f in _cpu_flags() if f.startswith(VECTOR_FLAG_PREFIXES)))


def cpu_isa() -> str:
    """The widest vector instruction set this CPU offers of those the renderer's and numpy's kernels choose between."""
    flags = _cpu_flags()
    for isa, flag in (("AVX512", "avx512f"), ("AVX2", "avx2"), ("SSE4.2", "sse4_2")):
        if flag in flags:
            return isa
    return platform.machine() or "unknown"


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def unlike(recorded: dict[str, Any] | None, here: dict[str, Any]) -> list[str]:
    """How this machine differs from the recorded one in what decides an evaluation's last digits ([] if alike).

    A record without a machine (results written before records kept one) was made on the
    development machine with AVX2, unpinned.
    """
    recorded = recorded or {"cpu_isa": "AVX2", "pinned": False}
    return [
        _difference(key, recorded.get(key), here.get(key))
        for key in LIKENESS_KEYS
        if key in recorded and recorded.get(key) != here.get(key)
    ]


def _difference(key: str, there: Any, here: Any) -> str:
    # long lists: the flags one side lacks
    if key == "cpu_features" and isinstance(there, str) and isinstance(here, str):
        a, b = set(there.split()), set(here.split())
        return f"cpu_features {' '.join(sorted(a - b)) or '-'} there only, {' '.join(sorted(b - a)) or '-'} here only"
    return f"{key} {there} there, {here} here"
