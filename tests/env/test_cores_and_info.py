"""Workers get disjoint cores by default; `visualenv info` reports what Blender can render on and never crashes;
the GPU says when it must compile kernels first."""

from __future__ import annotations

import json
import multiprocessing
import os
import sys

import numpy as np
import psutil
import pytest
from click.testing import CliRunner

from visualenv.cli import main
from visualenv.env import cores
from visualenv.env.vector import make_vec, warn_gpu_workers
from visualenv.tools.info import format_report, gather

TWO_CORES = pytest.mark.skipif(
    not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2, reason="needs Linux and 2 cores"
)


@pytest.mark.parametrize(
    "usable, n, shares",
    [
        (range(16), 16, [(i,) for i in range(16)]),
        (range(16), 4, [(0, 1, 2, 3), (4, 5, 6, 7), (8, 9, 10, 11), (12, 13, 14, 15)]),
        (range(16), 3, [(0, 1, 2, 3, 4), (5, 6, 7, 8, 9), (10, 11, 12, 13, 14, 15)]),
        ([2, 5], 3, [(2,), (5,), (2,)]),  # more workers than cores: one core each, round robin
        ([2, 5, 7], 1, [None]),  # one worker: nothing to keep apart
        ([0], 2, [None, None]),  # one core: nothing to choose
    ],
)
def test_workers_get_disjoint_shares_of_the_usable_cores(monkeypatch, usable, n, shares):
    monkeypatch.setattr(cores.os, "sched_getaffinity", lambda pid: set(usable), raising=False)
    assert cores.worker_cores(n) == shares
    assert cores.worker_cores(n, pin=False) == [None] * n
    got = [s for s in cores.worker_cores(n) if s]
    if n <= len(list(usable)):
        assert sum(len(s) for s in got) in (0, len(list(usable))) and len({c for s in got for c in s}) == sum(
            len(s) for s in got
        )
    assert [cores.render_threads(s, n) for s in shares] == [len(s) if s else cores.default_threads(n) for s in shares]


def _thread_cpu_ticks(pid: int) -> dict[int, int]:
    ticks = {}
    for thread in psutil.Process(pid).threads():
        try:
            with open(f"/proc/{pid}/task/{thread.id}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            ticks[thread.id] = int(fields[11]) + int(fields[12])
        except OSError:
            pass
    return ticks


@pytest.mark.blender
@TWO_CORES
def test_vector_env_workers_are_confined_by_default_and_run_few_busy_threads():
    """Two workers get their own halves of this process's cores (one each on two cores, four each on eight), Blender's
    threads included, and no thread pool sized to the whole machine runs."""
    ours = os.sched_getaffinity(0)
    shares = cores.worker_cores(2)
    vec = make_vec("VisualCartPole-v0", 2)
    try:
        vec.reset(seed=0)
        for _ in range(20):
            vec.step(np.array([0, 1]))
        pids = [p.pid for p in vec.processes]
        affinity = [tuple(sorted(psutil.Process(pid).cpu_affinity())) for pid in pids]
        assert affinity == shares and not set(affinity[0]) & set(affinity[1])
        for pid, share in zip(pids, shares):  # Blender's own threads too, not only the main one
            assert all(os.sched_getaffinity(t.id) == set(share) for t in psutil.Process(pid).threads())
        before = [_thread_cpu_ticks(pid) for pid in pids]
        for i in range(300):
            vec.step(np.array([i % 2, (i + 1) % 2]))
        after = [_thread_cpu_ticks(pid) for pid in pids]
        for b, a, share in zip(before, after, shares):
            busy = [tid for tid in a if a[tid] - b.get(tid, 0) > 2]  # threads that ran more than 20 ms over 300 steps
            assert 1 <= len(busy) <= 1 + len(share), (
                busy,
                a,
                b,
            )  # the main thread and Cycles' render threads, one per core of its share
    finally:
        vec.close()
    assert os.sched_getaffinity(0) == ours  # Gymnasium builds one env in the parent: it must not confine us


def _claim(queue, release) -> None:
    core = cores.claim_core()
    queue.put((core, sorted(os.sched_getaffinity(0))))
    release.wait(120)  # hold the claim while the others try


@TWO_CORES
def test_processes_placed_by_others_claim_distinct_cores(tmp_path, monkeypatch):
    """RLlib's EnvRunners are placed by Ray: each claims a core no other visualenv process holds."""
    monkeypatch.setenv(
        "TMPDIR", str(tmp_path)
    )  # the claims' lock files of these processes alone, not of others on the machine
    context = multiprocessing.get_context("spawn")
    queue, release = context.Queue(), context.Event()
    workers = [context.Process(target=_claim, args=(queue, release)) for _ in range(len(os.sched_getaffinity(0)) + 1)]
    for w in workers:
        w.start()
    results = [queue.get(timeout=60) for _ in workers]
    release.set()
    for w in workers:
        w.join(timeout=30)
    claimed = [core for core, _ in results if core is not None]
    assert sorted(claimed) == sorted(os.sched_getaffinity(0))  # every core once
    assert all(affinity == [core] for core, affinity in results if core is not None)
    assert sum(core is None for core, _ in results) == 1  # the extra process claims nothing and stays unconfined


@pytest.mark.parametrize(
    "facts, expected",
    [
        (
            (
                "CUDA",
                ("sm_75", "sm_89"),
                ("sm_90",),
                (("~/.nv/ComputeCache", False), ("/var/tmp/OptixCache_root", False)),
            ),
            "sm_90",
        ),
        (("OPTIX", ("sm_75", "sm_89"), ("sm_90",), (("~/.nv/ComputeCache", False),)), "no CUDA binary for sm_90"),
        (
            ("OPTIX", ("sm_75", "sm_89", "sm_90"), ("sm_90",), (("~/.nv/ComputeCache", False),)),
            None,
        ),  # OptiX's own modules: seconds
        (
            ("CUDA", ("sm_75", "sm_89"), ("sm_90",), (("~/.nv/ComputeCache", True),)),
            None,
        ),  # the driver's cache serves it
        (("CUDA", ("sm_75", "sm_89"), ("sm_89",), (("~/.nv/ComputeCache", False),)), None),  # a shipped binary
        (("HIP", (), (), (("~/.nv/ComputeCache", False),)), None),
    ],
)
@pytest.mark.blender
def test_the_first_gpu_render_says_when_it_compiles_kernels(facts, expected):
    devices = pytest.importorskip("visualenv.render.blender.runtime.devices", reason="the Blender backend needs bpy")
    kernel_facts = devices.KernelFacts(*facts)
    why = devices.kernels_to_compile(kernel_facts)
    notice = devices.compile_notice(kernel_facts)
    if expected is None:
        assert why is None and notice is None
    else:
        assert expected in why and expected in notice
        assert "once per machine" in notice and "ComputeCache" in notice and "visualenv info --warm-gpu" in notice


def test_several_gpu_workers_are_told_once_how_to_share_a_gpu(capsys, monkeypatch):
    from visualenv.env import vector

    monkeypatch.setattr(vector, "_warned_gpu", False)
    warn_gpu_workers("VisualCartPole-v0", 1, {"device": "gpu"})
    warn_gpu_workers("VisualCartPole-v0", 4, {"device": "cpu"})
    warn_gpu_workers("VisualCartPole-v0", 4, {})  # the spec's device: cpu
    assert capsys.readouterr().err == ""
    warn_gpu_workers("VisualCartPole-v0", 4, {"device": "gpu"})
    warn_gpu_workers("VisualCartPole-v0", 4, {"device": "gpu"})
    err = capsys.readouterr().err
    assert err.count("share the GPU badly") == 1 and "docs/performance.md#which-device" in err


@pytest.mark.blender
def test_info_reports_versions_cores_and_blenders_devices():
    result = CliRunner().invoke(main, ["info"])
    assert result.exit_code == 0, result.output
    assert f"cores: {len(os.sched_getaffinity(0))} usable" in result.output and "Blender (bpy) 5.0.1" in result.output
    assert "Cycles CPU" in result.output and "Cycles CUDA" in result.output and "EEVEE/Workbench:" in result.output
    as_json = CliRunner().invoke(main, ["info", "--json"])
    report = json.loads(as_json.output)
    assert report["blender"]["cycles"]["CPU"] and "OPTIX" in report["blender"]["cycles"]
    context = report["blender"]["gpu_context"]
    assert "renderer" in context and isinstance(context["software"], bool)
    assert set(report["blender"]["kernel_caches"]) and report["cores"]["usable"] == len(os.sched_getaffinity(0))
    assert (
        report["blender"]["batches"] == {"available": True}
        and "batches (N envs per Cycles call, --batched): available" in result.output
    )


def test_info_survives_a_probe_that_crashes_or_hangs():
    crashed = gather(command=[sys.executable, "-c", "import os; os.abort()"])
    assert "exit code" in crashed["blender"]["error"] and crashed["python"]
    hung = gather(command=[sys.executable, "-c", "import time; time.sleep(60)"], timeout=2)
    assert "did not answer in 2 s" in hung["blender"]["error"]
    assert "Blender: the Blender probe" in format_report(hung)


def test_info_names_mujocos_version():
    mujoco = pytest.importorskip("mujoco")
    report = gather(command=[sys.executable, "-c", "pass"])
    assert (
        report["mujoco"] == mujoco.__version__ and f"MuJoCo {mujoco.__version__}" in format_report(report).splitlines()
    )
    assert "MuJoCo: not installed" in format_report(dict(report, mujoco=None))


def test_info_says_why_batches_are_unavailable():
    report = {
        "visualenv": "0",
        "python": "3.11",
        "machine": "x86_64",
        "cores": {"usable": 2, "machine": 2},
        "blender": {
            "bpy": "5.0.1",
            "cycles": {},
            "gpu_context": {"error": "none"},
            "batches": {"error": "RuntimeError: Cycles could not compile the batch's custom camera shader"},
        },
    }
    assert (
        "batches (N envs per Cycles call, --batched): unavailable (RuntimeError: Cycles could not compile"
        in format_report(report)
    )


def test_info_says_whether_cuda_mps_runs(tmp_path, monkeypatch):
    """CUDA's Multi-Process Service: not here, installed with its daemon stopped, or its daemon's control pipe present."""
    from visualenv.tools import info

    monkeypatch.setenv("CUDA_MPS_PIPE_DIRECTORY", str(tmp_path))
    monkeypatch.setattr(info.shutil, "which", lambda name: None)
    assert info.cuda_mps() == {"control": None, "pipe_directory": str(tmp_path), "daemon": False}
    report = gather(command=[sys.executable, "-c", "pass"])
    assert "CUDA MPS: not here" in format_report(report)
    monkeypatch.setattr(info.shutil, "which", lambda name: f"/usr/bin/{name}")
    assert "nvidia-cuda-mps-control -d" in format_report(dict(report, cuda_mps=info.cuda_mps()))
    (tmp_path / "control").touch()
    assert info.cuda_mps()["daemon"] and "its daemon runs" in format_report(dict(report, cuda_mps=info.cuda_mps()))
