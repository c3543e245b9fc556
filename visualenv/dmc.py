"""DeepMind Control's own interface over the DMC ids: :func:`load` gives a ``dm_env.Environment``.

Code written for dm_control (DrQ-v2, and most work built on ``suite.load``) takes a
``dm_env.Environment``: ``reset()`` and ``step(action)`` return ``TimeStep`` s, and
``observation_spec()``, ``action_spec()`` and ``physics`` describe it. Where such code wrote::

    env = suite.load("cartpole", "swingup", task_kwargs={"random": seed})
    env = pixels.Wrapper(env, pixels_only=True, render_kwargs=dict(height=84, width=84, camera_id=0))

it writes ``env = visualenv.dmc.load("cartpole", "swingup", task_kwargs={"random": seed})`` and gets the same
steps (states and rewards equal to dm_control's, ``tests/dmc/test_interface.py``) with frames rendered by Blender.
Its own wrappers (action repeat, frame stack, action scaling) go on top as before.

The episode ends as dm_control's does: ``LAST`` with discount 1.0 at the time limit (a truncation), discount
0.0 where the task terminates. ``step`` after ``LAST`` starts the next episode, as ``dm_env`` specifies. Needs the
``dmc`` extra (``dm_env``, which dm_control brings).
"""

from __future__ import annotations

import collections
from typing import Any, Mapping

import numpy as np

try:
    import dm_env
    from dm_env import specs
except ImportError as exc:  # pragma: no cover - the dmc extra is missing
    raise ImportError("visualenv.dmc needs dm_env: pip install 'visualenv[dmc]'") from exc

from visualenv.env.make import make
from visualenv.env.visual_env import VisualEnv
from visualenv.env.wrappers import FrameStack

#: dm_control's key of rendered frames (``pixels.Wrapper``) and of a flat state (``flat_observation=True``)
PIXELS_KEY, STATE_KEY = "pixels", "observations"


class Environment(dm_env.Environment):
    """A visualenv env seen through ``dm_env``: TimeSteps, specs and dm_control's ``physics``.

    ``pixels_only=False`` adds the state dm_control observes, flattened, under ``"observations"`` (dm_control's key
    with ``environment_kwargs={"flat_observation": True}``); an env made with ``render=False`` observes that alone.
    ``frame_stack`` k stacks frames on the channel axis, repeating the first frame at reset as Gymnasium's
    ``FrameStackObservation`` and DrQ-v2 do (``padding="zeros"``: SB3's zeros). The action spec is dm_control's:
    float64, unnamed.
    """

    def __init__(
        self,
        env: VisualEnv,
        *,
        seed: int | None = None,
        pixels_only: bool = True,
        frame_stack: int | None = None,
        padding: str = "first",
    ) -> None:
        self._env: Any = FrameStack(env, frame_stack, padding=padding) if frame_stack and frame_stack > 1 else env
        self._visual = env
        self._seed = seed
        #: the keys of an observation: the flat state (rendering off, or pixels_only=False), the frames (rendering)
        self._keys = ([] if pixels_only and env.uses_camera else [STATE_KEY]) + (
            [PIXELS_KEY] if env.uses_camera else []
        )
        self._needs_reset = True
        self._physics: Any = None
        size = env.program.physics.observe_size  # type: ignore[union-attr]
        shapes = {STATE_KEY: ((size,), np.float64), PIXELS_KEY: (self._env.observation_space.shape, np.uint8)}
        self._observation_spec = collections.OrderedDict((key, specs.Array(*shapes[key], key)) for key in self._keys)
        # the spec's float64 bounds, as dm_control's ctrlrange (the Box rounds them to float32: quadruped's -0.8, 1.1)
        low, high = np.array(env.program.continuous, np.float64).reshape(-1, 2).T
        self._action_spec = specs.BoundedArray(env.action_space.shape, np.float64, low, high)

    def reset(self) -> dm_env.TimeStep:
        seed, self._seed = self._seed, None  # the task's stream is seeded once, then goes on (task_kwargs' random)
        obs, _ = self._env.reset(seed=seed)
        self._needs_reset = False
        return dm_env.restart(self._observation(obs))

    def step(self, action: Any) -> dm_env.TimeStep:
        if self._needs_reset:
            return self.reset()
        obs, reward, terminated, truncated, _ = self._env.step(np.asarray(action, dtype=np.float64))
        observation = self._observation(obs)
        if terminated:
            self._needs_reset = True
            return dm_env.termination(float(reward), observation)
        if truncated:
            self._needs_reset = True
            return dm_env.truncation(float(reward), observation)
        return dm_env.transition(float(reward), observation)

    def observation_spec(self) -> Mapping[str, specs.Array]:
        return self._observation_spec

    def action_spec(self) -> specs.BoundedArray:
        return self._action_spec

    @property
    def physics(self) -> Any:
        """dm_control's ``Physics`` over the env's own MjData (named access: ``physics.named.data.qpos``)."""
        if self._physics is None:
            from dm_control.mujoco import Physics, wrapper  # the dmc extra's: only for state access

            self._physics = Physics(wrapper.MjData(self._visual.data))
        return self._physics

    @property
    def gym_env(self) -> VisualEnv:
        """The Gymnasium env under this interface."""
        return self._visual

    def close(self) -> None:
        self._env.close()

    def _observation(self, obs: Any) -> collections.OrderedDict:
        out: collections.OrderedDict = collections.OrderedDict()
        if STATE_KEY in self._keys:  # the env's observation, or computed beside its frames
            out[STATE_KEY] = self._visual.state_observation() if PIXELS_KEY in self._keys else obs
        if PIXELS_KEY in self._keys:
            out[PIXELS_KEY] = obs
        return out


def load(
    domain_name: str,
    task_name: str,
    task_kwargs: Mapping[str, Any] | None = None,
    *,
    render_kwargs: Mapping[str, Any] | None = None,
    pixels_only: bool = True,
    action_repeat: int = 1,
    frame_stack: int | None = None,
    padding: str = "first",
    **make_options: Any,
) -> Environment:
    """``DMC-<domain_name>-<task_name>-v0`` as ``suite.load`` + ``pixels.Wrapper`` give it.

    Args:
        task_kwargs: ``{"random": seed}`` seeds the task's stream at the first reset, as dm_control's does; other
            keys are refused (the spec fixes the task).
        render_kwargs: ``height``, ``width`` and ``camera_id`` as ``pixels.Wrapper`` takes them; they must be the
            spec's (84x84 from DrQ-v2's camera): the error says which the id renders.
        pixels_only: False adds the flat state under ``"observations"``; ``render=False`` (a make option) gives it
            alone, as ``suite.load`` with ``environment_kwargs={"flat_observation": True}`` does.
        action_repeat: the spec's steps per ``step()``; 1, dm_control's own, by default (DrQ-v2 repeats in its own
            wrapper).
        frame_stack, padding: frames stacked on the channel axis; at reset the first frame is repeated
            (``padding="first"``, Gymnasium's and DrQ-v2's convention) or the older slots are zeros (``"zeros"``).
        make_options: passed to :func:`visualenv.make` (``distractions``, ``device``, ``threads``...).
    """
    env_id = f"DMC-{domain_name}-{task_name}-v0"
    unknown = sorted(set(task_kwargs or {}) - {"random"})
    if unknown:
        raise ValueError(f"task_kwargs {unknown} are not taken: {env_id}'s spec fixes its task (only 'random' is)")
    seed = (task_kwargs or {}).get("random")
    if seed is not None and not isinstance(seed, (int, np.integer)):
        raise ValueError(f"task_kwargs['random'] must be an integer seed, got {seed!r}")
    env = make(env_id, action_repeat=action_repeat, **make_options)
    visual = env.unwrapped
    assert isinstance(visual, VisualEnv)
    if visual.uses_camera:
        _check_render_kwargs(visual, dict(render_kwargs or {}))
    elif render_kwargs:
        raise ValueError("render_kwargs need frames: this env was made with render=False")
    return Environment(
        visual,
        seed=None if seed is None else int(seed),
        pixels_only=pixels_only,
        frame_stack=frame_stack,
        padding=padding,
    )


def _check_render_kwargs(env: VisualEnv, render_kwargs: dict[str, Any]) -> None:
    """``pixels.Wrapper``'s render_kwargs, checked against what the spec renders (a spec's camera and size are fixed)."""
    observation = env.program.spec.observation
    assert observation is not None, "an env that renders has an observation camera"
    view = next(iter(observation.views().values()))
    width, height = view.resolution
    model = env.model
    names = [model.camera(i).name for i in range(model.ncam)]
    unknown = sorted(set(render_kwargs) - {"height", "width", "camera_id"})
    if unknown:
        raise ValueError(f"render_kwargs {unknown} are not taken: height, width and camera_id are")
    camera = render_kwargs.get("camera_id", names.index(view.camera) if view.camera in names else view.camera)
    wanted = (render_kwargs.get("height", height), render_kwargs.get("width", width))
    shown = names[camera] if isinstance(camera, int) and 0 <= camera < len(names) else camera
    if wanted != (height, width) or shown != view.camera:
        raise ValueError(
            f"{env.program.spec.id} renders {height}x{width} from camera {view.camera!r}"
            f" (camera_id {names.index(view.camera) if view.camera in names else '?'}), not {wanted[0]}x{wanted[1]}"
            f" from {shown!r}: the spec fixes its camera and size"
        )
