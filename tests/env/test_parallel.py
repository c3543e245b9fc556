"""Parallel envs: one Blender per worker process, clean shutdown, prompt errors when a worker dies."""

import os
import signal
import time

import numpy as np
import psutil
import pytest

import visualenv
from visualenv.errors import WorkerError
from visualenv.env.sb3_vec import make_sb3_vec
from visualenv.env.vector import make_vec

pytestmark = pytest.mark.blender


def children() -> set[int]:
    """Live child processes, except multiprocessing's resource tracker (it lives as long as we do)."""
    out = set()
    for p in psutil.Process().children(recursive=True):
        try:
            if p.status() != psutil.STATUS_ZOMBIE and "resource_tracker" not in " ".join(p.cmdline()):
                out.add(p.pid)
        except psutil.NoSuchProcess:
            pass
    return out


def test_async_vector_env_renders_in_workers_and_closes_them():
    before = children()
    vec = visualenv.make_vec("VisualCartPole-v0", 2)  # the public helper
    try:
        obs, _ = vec.reset(seed=[1, 2])
        assert obs.shape == (2, 100, 100, 1) and obs.dtype == np.uint8
        # different seeds, different starting states: the two frames differ somewhere
        for _ in range(5):
            obs, rewards, terminated, truncated, infos = vec.step(np.array([0, 1]))
        assert rewards.tolist() == [1.0, 1.0]
        assert not np.array_equal(obs[0], obs[1])
        assert len(children() - before) >= 2
    finally:
        vec.close()
    deadline = time.time() + 10
    while children() - before and time.time() < deadline:
        time.sleep(0.1)
    assert not (children() - before), "worker processes left behind"


def test_async_vector_env_matches_a_single_env():
    vec = make_vec("VisualCartPole-v0", 2)
    single = visualenv.make("VisualCartPole-v0")
    try:
        obs, _ = vec.reset(seed=[7, 8])
        ref, _ = single.reset(seed=7)
        np.testing.assert_array_equal(obs[0], ref)
        for action in [1, 0, 1, 1]:
            obs, *_ = vec.step(np.array([action, 0]))
            ref, *_ = single.step(action)
        np.testing.assert_array_equal(obs[0], ref)
    finally:
        vec.close()
        single.close()


def test_sb3_subproc_vec_env_with_frame_stack():
    """SB3's VecFrameStack over the workers: the newest frame last, each step shifting the others one place left."""
    vec = make_sb3_vec("Goalie-v0", 2, seed=0, frame_stack=4)
    try:
        first = vec.reset()
        assert first.shape == (2, 100, 100, 4) and first.dtype == np.uint8
        assert not first[..., :3].any() and first[..., 3].any()  # after a reset: zeros, then the first frame
        frames = [first]
        for _ in range(2):
            obs, rewards, dones, infos = vec.step(np.array([0, 1]))
            assert obs.shape == (2, 100, 100, 4) and len(infos) == 2 and not dones.any()
            frames.append(obs)
        last = frames[-1]
        assert np.array_equal(last[..., 1], first[..., 3]) and np.array_equal(last[..., 2], frames[1][..., 3])
        assert not last[..., 0].any() and not np.array_equal(last[..., 3], last[..., 2])  # the ball moved
    finally:
        vec.close()


@pytest.mark.timeout(120)
def test_a_killed_worker_raises_promptly_instead_of_hanging():
    vec = make_vec("VisualCartPole-v0", 2)
    try:
        vec.reset(seed=0)
        victim = vec.processes[0].pid
        os.kill(victim, signal.SIGKILL)
        tried = 0
        with pytest.raises(WorkerError, match=rf"worker #0 \(pid {victim}, exit code -9\) died during step"):
            for _ in range(3):
                tried += 1
                vec.step(np.array([0, 1]))
        assert tried == 1  # the first step after the death says so (a hang would meet the test's timeout)
    finally:
        vec.close()
    assert not any(p.is_alive() for p in vec.processes)


def test_default_threads_share_the_cores_this_process_may_use(monkeypatch):
    from visualenv.env import cores

    monkeypatch.setattr(cores.os, "cpu_count", lambda: 64)
    monkeypatch.setattr(cores.os, "sched_getaffinity", lambda pid: set(range(8)), raising=False)
    assert cores.default_threads(2) == 4  # the 8 cores of our affinity mask, not the machine's 64
    monkeypatch.setattr(cores.os, "sched_getaffinity", lambda pid: {3}, raising=False)
    assert cores.default_threads(2) == 1
