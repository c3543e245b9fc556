"""`visualenv play`: run episodes with a random or trained policy and record them."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from visualenv.build import side_by_side
from visualenv.errors import VisualEnvError

VIDEO_FORMATS = (".gif", ".mp4")


@dataclass
class Episode:
    ret: float
    length: int
    success: bool
    outcome: str | None


def with_view(loaded: Any, *, preset: str | None = None, size: int | None = None) -> Any:
    """The spec with its human view's preset and/or size (longer side, aspect kept) changed.

    The 'quality' view takes seconds per frame on a CPU; 'fast' at 200 px
    records a 200-step episode in a few seconds.
    """
    view = loaded.spec.render.view
    update: dict[str, Any] = {}
    if preset:
        update["preset"] = preset
    if size:
        width, height = view.resolution
        scale = size / max(width, height)
        update["resolution"] = [max(1, round(width * scale)), max(1, round(height * scale))]
    if not update:
        return loaded
    render = loaded.spec.render.model_copy(update={"view": view.model_copy(update=update)})
    return replace(loaded, spec=loaded.spec.model_copy(update={"render": render}))


def play(spec: str, *, model_path: str | None = None, algo: str = "ppo", episodes: int = 3, seed: int = 0,
         record: str | None = None, fps: int = 15, max_frames: int = 2000, view_preset: str | None = None,
         view_size: int | None = None) -> list[Episode]:
    """Play `episodes`; with `record`, save a GIF/MP4 of the view beside the agent's observation."""
    from visualenv.compiler import VisualEnv
    from visualenv.registration import resolve
    from visualenv.spec import load_spec
    from visualenv.wrappers import FrameStack

    if record and Path(record).suffix.lower() not in VIDEO_FORMATS:
        raise VisualEnvError(f"cannot record {record}: expected a file ending in {' or '.join(VIDEO_FORMATS)}")
    model = None
    if model_path:
        from visualenv.training import algorithm_class

        try:
            model = algorithm_class(algo).load(model_path, device="cpu")
        except Exception as exc:  # SB3 raises whatever its unpickling met: report it, whatever it is
            raise VisualEnvError(f"cannot load {model_path} as a {algo.upper()} model: {exc}") from None
    loaded = with_view(load_spec(resolve(spec)), preset=view_preset, size=view_size)
    env: Any = VisualEnv(loaded, render_mode="rgb_array")
    if model is not None:
        try:
            env = _stacked_like(env, model, model_path)
        except BaseException:
            env.close()
            raise
    env.action_space.seed(seed)
    frames: list[np.ndarray] = []
    results = []
    try:
        for episode in range(episodes):
            obs, info = env.reset(seed=seed + episode)
            ret, length = 0.0, 0
            while True:
                if record and len(frames) < max_frames:
                    latest = obs[..., -1:] if model is not None and obs.shape[-1] > 1 and isinstance(env, FrameStack) else obs
                    frames.append(side_by_side(latest, env.render()))
                action = model.predict(obs, deterministic=True)[0] if model is not None else env.action_space.sample()
                obs, reward, terminated, truncated, info = env.step(action)
                ret += float(reward)
                length += 1
                if terminated or truncated:
                    break
            results.append(Episode(ret, length, bool(info.get("is_success")), info.get("outcome")))
    finally:
        env.close()
    if record and frames:
        save_video(frames, record, fps)
    return results


def _stacked_like(env: Any, model: Any, model_path: str) -> Any:
    """`env` with the frame stack the model was trained on; a model of another env is an error, not a crash mid-episode."""
    from stable_baselines3.common.preprocessing import is_image_space_channels_first

    from visualenv.wrappers import FrameStack

    space = model.observation_space
    have = env.observation_space.shape
    want = space.shape[0] if is_image_space_channels_first(space) else space.shape[-1]
    if len(have) == len(space.shape) and want != have[-1] and want % have[-1] == 0:
        env = FrameStack(env, want // have[-1])
    shape = env.observation_space.shape
    fits = space.shape in (shape, shape[-1:] + shape[:-1])  # SB3 also takes channel-last images for a channel-first model
    actions, ours = model.action_space, env.action_space
    if not fits or type(actions) is not type(ours) or actions.shape != ours.shape or getattr(actions, "n", None) != getattr(ours, "n", None):
        raise VisualEnvError(f"{model_path} was trained on observations {space.shape} and actions {actions}; "
                             f"this env has observations {env.observation_space.shape} and actions {ours}")
    return env


def save_video(frames: list[np.ndarray], path: str | Path, fps: int) -> Path:
    """GIF or MP4 by the file's extension (imageio)."""
    import imageio.v3 as iio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        iio.imwrite(path, np.stack(frames), duration=1000 / fps, loop=0)
    else:
        iio.imwrite(path, np.stack(frames), fps=fps, codec="libx264", macro_block_size=1)
    return path
