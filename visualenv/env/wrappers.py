"""Observation wrappers for image envs, in the layout Stable-Baselines3 expects.

SB3's CnnPolicy wants uint8 images of shape (H, W, C) and stacks frames on the
channel axis (its ``VecFrameStack``). Gymnasium's ``FrameStackObservation``
adds a leading axis instead, which SB3 does not accept as an image, so
:class:`FrameStack` stacks on the last axis: oldest frame first, newest last,
and on reset the first frame fills every slot.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from PIL import Image

from visualenv.render.pixels import to_grayscale


def _image_box(space: spaces.Space) -> spaces.Box:
    if not (isinstance(space, spaces.Box) and space.dtype == np.uint8 and len(space.shape) == 3):
        raise TypeError(f"expected a uint8 image space (H, W, C), got {space}")
    return space


def subspaces(space: spaces.Space) -> dict[str, spaces.Space]:
    """The spaces of a Dict observation by key; a single observation under the key ''."""
    return dict(space.spaces) if isinstance(space, spaces.Dict) else {"": space}


def _map_space(space: spaces.Space, fn: Any) -> spaces.Space:
    if isinstance(space, spaces.Dict):
        return spaces.Dict({k: fn(_image_box(s)) for k, s in space.spaces.items()})
    return fn(_image_box(space))


def _map_obs(obs: Any, fn: Any) -> Any:
    if isinstance(obs, dict):
        return {k: fn(v) for k, v in obs.items()}
    return fn(obs)


class Grayscale(gym.ObservationWrapper):
    """RGB (H, W, 3) -> grayscale (H, W, 1) with the renderer's BT.601 luma (:func:`visualenv.render.pixels.to_grayscale`); 1-channel images pass through."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.observation_space = _map_space(
            env.observation_space, lambda s: spaces.Box(0, 255, s.shape[:2] + (1,), np.uint8)
        )

    @staticmethod
    def convert(image: np.ndarray) -> np.ndarray:
        if image.shape[-1] == 1:
            return image
        return to_grayscale(image)

    def observation(self, observation: Any) -> Any:
        return _map_obs(observation, self.convert)


class Resize(gym.ObservationWrapper):
    """Resize images to (width, height) with area averaging (Pillow)."""

    def __init__(self, env: gym.Env, size: tuple[int, int]):
        super().__init__(env)
        self.size = (int(size[0]), int(size[1]))
        w, h = self.size
        self.observation_space = _map_space(
            env.observation_space, lambda s: spaces.Box(0, 255, (h, w, s.shape[2]), np.uint8)
        )

    def _resize(self, image: np.ndarray) -> np.ndarray:
        if image.shape[1] == self.size[0] and image.shape[0] == self.size[1]:
            return image
        channels = image.shape[2]
        mode_image = Image.fromarray(image[..., 0] if channels == 1 else image)
        out = np.asarray(
            mode_image.resize(self.size, Image.Resampling.BOX if self._shrinks(image) else Image.Resampling.BILINEAR)
        )
        return out[..., None] if channels == 1 else out

    def _shrinks(self, image: np.ndarray) -> bool:
        return image.shape[1] >= self.size[0] and image.shape[0] >= self.size[1]

    def observation(self, observation: Any) -> Any:
        return _map_obs(observation, self._resize)


class FrameStack(gym.Wrapper):
    """Stack the last `depth` frames on the channel axis: (H, W, C) -> (H, W, C * depth).

    Oldest first: channels ``[0:C]`` are the frame from ``depth - 1`` steps ago,
    the last ``C`` channels are the newest. By default reset zeroes the older slots, as
    SB3's ``VecFrameStack`` does, so an agent trained through SB3 sees at play
    time what it saw in training (a repeated first frame instead reads as a
    still ball to the Goalie agent, which then misses). ``padding="first"`` repeats the
    first frame instead, as Gymnasium's ``FrameStackObservation`` and DrQ-v2 do.
    """

    def __init__(self, env: gym.Env, depth: int = 4, *, padding: str = "zeros"):
        super().__init__(env)
        if depth < 1:
            raise ValueError("depth must be at least 1")
        if padding not in ("zeros", "first"):
            raise ValueError(f"padding must be 'zeros' or 'first', got {padding!r}")
        self.depth = depth
        self.padding = padding
        self.observation_space = _map_space(
            env.observation_space, lambda s: spaces.Box(0, 255, s.shape[:2] + (s.shape[2] * depth,), np.uint8)
        )
        self._frames: deque[Any] = deque(maxlen=depth)

    @property
    def latest(self) -> Any:
        """The newest frame as the env gave it (what a recording shows)."""
        return self._frames[-1]

    def _stacked(self) -> Any:
        first = self._frames[0]
        if isinstance(first, dict):
            return {k: np.concatenate([f[k] for f in self._frames], axis=-1) for k in first}
        return np.concatenate(list(self._frames), axis=-1)

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._frames.clear()
        for _ in range(self.depth - 1):
            self._frames.append(_zeros_like(obs) if self.padding == "zeros" else obs)
        self._frames.append(obs)
        return self._stacked(), info

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._frames.append(obs)
        return self._stacked(), reward, terminated, truncated, info


def _zeros_like(obs: Any) -> Any:
    return {k: np.zeros_like(v) for k, v in obs.items()} if isinstance(obs, dict) else np.zeros_like(obs)


def wrap_observation(
    env: gym.Env, *, grayscale: bool = False, resize: tuple[int, int] | None = None, frame_stack: int | None = None
) -> gym.Env:
    """Apply the standard image pipeline: grayscale, then resize, then frame stack."""
    if grayscale:
        env = Grayscale(env)
    if resize:
        env = Resize(env, resize)
    if frame_stack and frame_stack > 1:
        env = FrameStack(env, frame_stack)
    return env


class VectorFrameStack(gym.vector.VectorObservationWrapper):
    """:class:`FrameStack` for a vector env whose envs reset on the step after their episode ends (Gymnasium's NEXT_STEP).

    Each env's stack is its own: an env that resets (with the vector env, or on its
    own after an episode's end) starts with zeroed older slots, as ``FrameStack`` and
    SB3's ``VecFrameStack`` do. Box observations (N, H, W, C) -> (N, H, W, C * depth).
    """

    def __init__(self, env: gym.vector.VectorEnv, depth: int = 4):
        super().__init__(env)
        space = env.single_observation_space
        if not isinstance(space, spaces.Box) or len(space.shape) != 3:
            raise ValueError(f"VectorFrameStack stacks images (H, W, C), not {space}")
        if depth < 1:
            raise ValueError("depth must be at least 1")
        self.depth = depth
        h, w, c = space.shape
        self.single_observation_space = spaces.Box(0, 255, (h, w, c * depth), np.uint8)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, env.num_envs)
        self._stack = np.zeros((env.num_envs, h, w, c * depth), dtype=np.uint8)
        self._channels = c
        self._ended = np.zeros(env.num_envs, dtype=bool)

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._stack[:] = 0
        self._stack[..., -self._channels :] = obs
        self._ended[:] = False
        return self._stack.copy(), info

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        c = self._channels
        self._stack[:, :, :, :-c] = self._stack[:, :, :, c:]
        self._stack[self._ended, :, :, :-c] = 0  # these envs reset in this step: a new episode's first frame
        self._stack[..., -c:] = obs
        self._ended = np.logical_or(terminated, truncated)
        return self._stack.copy(), rewards, terminated, truncated, info

    def observations(self, observations: Any) -> Any:  # the step and reset above do the work
        return observations
