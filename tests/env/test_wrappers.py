"""Observation wrappers: shapes, stacking order, reset padding, SB3 compatibility.

These use a tiny synthetic image env whose frame t is filled with the value t,
so the order of stacked frames can be read off the pixels.
"""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from visualenv.env.wrappers import FrameStack, Grayscale, Resize, wrap_observation


class Counter(gym.Env):
    """Frame t is an (H, W, C) image filled with t."""

    def __init__(self, shape=(6, 8, 3), dict_obs=False):
        self.shape = shape
        box = spaces.Box(0, 255, shape, np.uint8)
        self.observation_space = spaces.Dict({"a": box, "b": box}) if dict_obs else box
        self.action_space = spaces.Discrete(2)
        self.dict_obs = dict_obs
        self.t = 0

    def _obs(self):
        frame = np.full(self.shape, self.t, np.uint8)
        return {"a": frame, "b": frame + 100} if self.dict_obs else frame

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 10
        return self._obs(), {}

    def step(self, action):
        self.t += 1
        return self._obs(), 0.0, False, False, {}


def test_frame_stack_matches_sb3_vec_frame_stack():
    # play and visualenv.make(frame_stack=...) must show an SB3-trained agent what VecFrameStack showed it
    vec_env = pytest.importorskip("stable_baselines3.common.vec_env")
    ours = FrameStack(Counter((6, 8, 1)), 4)
    theirs = vec_env.VecFrameStack(vec_env.DummyVecEnv([lambda: Counter((6, 8, 1))]), 4)
    assert np.array_equal(ours.reset()[0], theirs.reset()[0])
    for _ in range(5):
        assert np.array_equal(ours.step(0)[0], theirs.step(np.array([0]))[0][0])


def test_frame_stack_is_on_the_channel_axis_oldest_first():
    env = FrameStack(Counter((6, 8, 1)), 4)
    assert env.observation_space.shape == (6, 8, 4) and env.observation_space.dtype == np.uint8
    obs, _ = env.reset()
    assert obs.shape == (6, 8, 4) and obs[0, 0].tolist() == [0, 0, 0, 10]  # reset pads with zeros, as SB3 does
    obs = env.step(0)[0]
    assert obs[0, 0].tolist() == [0, 0, 10, 11]
    for _ in range(3):
        obs = env.step(0)[0]
    assert obs[0, 0].tolist() == [11, 12, 13, 14]
    assert env.observation_space.contains(obs)


def test_frame_stack_of_rgb_keeps_channels_together():
    env = FrameStack(Counter((4, 4, 3)), 2)
    env.reset()
    obs = env.step(0)[0]
    assert obs.shape == (4, 4, 6) and obs[0, 0].tolist() == [10, 10, 10, 11, 11, 11]


def test_frame_stack_of_dict_observations():
    env = FrameStack(Counter((4, 4, 1), dict_obs=True), 3)
    obs, _ = env.reset()
    obs = env.step(0)[0]
    assert obs["a"][0, 0].tolist() == [0, 10, 11] and obs["b"][0, 0].tolist() == [0, 110, 111]
    assert env.observation_space.contains(obs)


def test_grayscale_uses_bt601_luma():
    class Red(Counter):
        def _obs(self):
            frame = np.zeros(self.shape, np.uint8)
            frame[..., 0] = 200
            return frame

    env = Grayscale(Red((4, 4, 3)))
    obs, _ = env.reset()
    assert obs.shape == (4, 4, 1) and obs.dtype == np.uint8 and obs[0, 0, 0] == round(0.299 * 200)
    assert env.observation_space.shape == (4, 4, 1)


def test_resize_changes_width_and_height():
    env = Resize(Counter((100, 80, 1)), (40, 50))
    obs, _ = env.reset()
    assert obs.shape == (50, 40, 1) and env.observation_space.shape == (50, 40, 1) and (obs == 10).all()


def test_pipeline_order_and_sb3_accepts_the_stack():
    from stable_baselines3.common.preprocessing import is_image_space

    env = wrap_observation(Counter((64, 64, 3)), grayscale=True, resize=(36, 36), frame_stack=4)
    assert env.observation_space.shape == (36, 36, 4)
    assert is_image_space(env.observation_space)
    # Gymnasium's own FrameStackObservation puts frames on a leading axis, which SB3 does not take as an image
    leading = gym.wrappers.FrameStackObservation(Grayscale(Counter((36, 36, 3))), 4)
    assert not is_image_space(leading.observation_space)


def test_rejects_non_image_spaces():
    class Vector(Counter):
        def __init__(self):
            super().__init__()
            self.observation_space = spaces.Box(-1, 1, (4,), np.float32)

    with pytest.raises(TypeError, match="uint8 image"):
        FrameStack(Vector(), 4)
