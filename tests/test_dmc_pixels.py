"""DMC-cartpole-swingup-v0 from pixels: 84x84 RGB through dm_control's camera 0, rendered by Blender.

The cart is where MuJoCo's camera model puts it (camera "fixed": 4 m in front, fovy 45 degrees,
so x metres along the rail are about 25.3 x pixels from the centre column), the model's skybox is
behind it, and a frame stack stacks the frames. Parity with dm_control's state is
tests/test_dmc_parity.py; dm_control's lighting is matched in a later stage (docs/dmc.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("mujoco")

import visualenv  # noqa: E402

ID = "DMC-cartpole-swingup-v0"
SIZE = 84
#: pixels per metre along the rail at the cart's depth (4 m), from the camera's fovy of 45 degrees
PER_METRE = (SIZE / 2) / (4 * math.tan(math.radians(45 / 2)))


def cart_column(frame: np.ndarray) -> float:
    """The column of the cart's middle: the warm (red over blue) pixels of the rows the cart's box covers."""
    rows = frame[SIZE // 2 - 3: SIZE // 2 + 3].astype(int)
    warm = (rows[..., 0] > rows[..., 2] + 40) & (rows[..., 0] > 120)
    assert warm.sum() >= 20, f"the cart is not in view: {warm.sum()} warm pixels"
    return float(np.nonzero(warm)[1].mean())


def test_the_cart_is_seen_where_mujocos_camera_puts_it_in_front_of_the_sky() -> None:
    env = visualenv.make(ID, frame_stack=3)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (SIZE, SIZE, 9) and obs.dtype == np.uint8 and env.observation_space.shape == (SIZE, SIZE, 9)
    data = env.unwrapped.data
    frame = obs[..., -3:]
    expected = (SIZE - 1) / 2 + PER_METRE * data.qpos[0]
    assert abs(cart_column(frame) - expected) < 2.0
    sky = frame[:20].reshape(-1, 3).astype(float).mean(axis=0)
    assert sky[2] > sky[0] + 20, f"the top of the frame is not the model's blue sky: {sky}"
    for _ in range(3):  # pushed right for 24 control steps (0.24 s), the pole still below the rail
        obs, *_ = env.step(np.array([1.0], dtype=np.float32))
    assert data.qpos[0] > 0.15
    moved = obs[..., -3:]
    assert abs(cart_column(moved) - ((SIZE - 1) / 2 + PER_METRE * data.qpos[0])) < 2.0
    assert cart_column(moved) > cart_column(frame) + 4
    assert not np.array_equal(obs[..., :3], obs[..., -3:])  # the stack holds earlier frames
    env.close()
