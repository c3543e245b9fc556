"""Every bundled id runs batched, the DMC tasks whose camera tracks the body (cheetah, walker) included.

A MuJoCo camera that tracks a body (``trackcom``: cheetah's and walker's "side") moves with each env's body: a
batch moves each env's copy of the scene so that its camera stands where the tiles camera looks from, so env k's
tile is seen from env k's own camera, as one env sees it. The cheetah runs far enough (2 m) that a camera that did
not follow would see it leave the frame.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("mujoco")

import visualenv  # noqa: E402

pytestmark = pytest.mark.blender

CHEETAH = "DMC-cheetah-run-v0"


def gait(step: int, phase: float) -> np.ndarray:
    """A periodic action of the cheetah's six joints: with phase 1.57 it runs backwards about 2 m in 40 steps."""
    return np.sin(0.5 * step + np.array([0.0, phase, 2 * phase, phase + np.pi, 2 * phase + np.pi, 0.0])).astype(
        np.float32
    )


def body(frame: np.ndarray) -> np.ndarray:
    """The cheetah's pixels: its warm colour (dm_control's 'self' material, .7 .5 .3) over the blue sky and floor."""
    pixels = frame.astype(int)
    return (pixels[..., 0] > pixels[..., 2] + 60) & (pixels[..., 0] > 100)


def test_each_cheetah_tile_is_its_own_env_seen_from_its_own_tracking_camera() -> None:
    n, steps = 4, 40
    phases = [1.57, 0.0, None, 3.14]  # None: random actions
    batch = visualenv.make_vec(CHEETAH, n, batched=True)
    alone = [visualenv.make(CHEETAH) for _ in range(n)]
    rng = np.random.default_rng(0)
    try:
        tiles, _ = batch.reset(seed=10)
        frames = [env.reset(seed=10 + k)[0] for k, env in enumerate(alone)]
        for t in range(steps):
            actions = np.stack(
                [gait(t, p) if p is not None else rng.uniform(-1, 1, 6).astype(np.float32) for p in phases]
            )
            tiles, *_ = batch.step(actions)
            frames = [env.step(actions[k])[0] for k, env in enumerate(alone)]
        xs = [float(env.unwrapped.data.qpos[0]) for env in alone]
        assert xs[0] < -1.5, (
            f"the cheetah did not run: x = {xs}"
        )  # a camera left where it started would see it out of the frame
        for k in range(n):
            mine, theirs = body(tiles[k]), body(frames[k])
            assert theirs.sum() > 150, f"env {k}: the cheetah is not in its own frame ({theirs.sum()} pixels)"
            iou = (mine & theirs).sum() / (mine | theirs).sum()
            mean = np.abs(tiles[k].astype(int) - frames[k].astype(int)).mean()
            assert iou > 0.95 and mean < 1.0, (
                f"env {k} (x = {xs[k]:.2f} m): IoU {iou:.3f}, mean |difference| {mean:.2f}"
            )
            columns = np.nonzero(theirs)[1]
            assert 20 < columns.mean() < 64, (
                f"env {k}: the tracking camera lost the body (centre column {columns.mean():.1f})"
            )
    finally:
        batch.close()
        for env in alone:
            env.close()


@pytest.mark.parametrize(
    "ident", ["DMC-walker-walk-v0", "DMC-pendulum-swingup-v0", "DMC-hopper-hop-v0", "DMC-humanoid-walk-v0"]
)
def test_a_dmc_batch_shows_each_env_as_it_is_alone(ident: str) -> None:
    """Walker's tracking camera; pendulum, one of the models DrQ-v2's tasks added (spot-lit, seen from above); hopper's
    camera, a child of the world body that tracks the whole model's centre of mass; the humanoid's, on a free body."""
    batch = visualenv.make_vec(ident, 2, batched=True)
    alone = [visualenv.make(ident) for _ in range(2)]
    rng = np.random.default_rng(1)
    try:
        tiles, _ = batch.reset(seed=4)
        frames = [env.reset(seed=4 + k)[0] for k, env in enumerate(alone)]
        for _ in range(10):
            actions = rng.uniform(-1, 1, (2, *batch.single_action_space.shape)).astype(np.float32)
            tiles, *_ = batch.step(actions)
            frames = [env.step(actions[k])[0] for k, env in enumerate(alone)]
        for k in range(2):
            mean = np.abs(tiles[k].astype(int) - frames[k].astype(int)).mean()
            assert mean < 1.0, f"env {k}: mean |difference| {mean:.2f}"
    finally:
        batch.close()
        for env in alone:
            env.close()


@pytest.mark.parametrize(
    "ident", sorted(i.removeprefix("visualenv/") for i in gym.registry if i.startswith("visualenv/"))
)
def test_every_bundled_id_runs_batched(ident: str) -> None:
    batch = visualenv.make_vec(ident, 2, batched=True)
    try:
        obs, _ = batch.reset(seed=0)
        for _ in range(2):
            obs, rewards, terminated, truncated, _ = batch.step(batch.action_space.sample())
        space = batch.single_observation_space
        frames = obs if isinstance(obs, dict) else {"": obs}
        shapes = (
            {key: sub.shape for key, sub in space.spaces.items()}
            if isinstance(space, gym.spaces.Dict)
            else {"": space.shape}
        )
        for key, frame in frames.items():
            assert frame.shape == (2, *shapes[key]) and frame.dtype == np.uint8, (key, frame.shape)
            assert frame.std() > 0, f"{ident}: a blank observation ({key or 'the camera'})"
        assert rewards.shape == terminated.shape == truncated.shape == (2,)
    finally:
        batch.close()
