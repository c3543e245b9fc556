"""`visualenv play`: run episodes with a random or trained policy and record them."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from visualenv.files import make_dir
from visualenv.images import side_by_side
from visualenv.errors import VisualEnvError
from visualenv.wrappers import subspaces

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


def check_recording(path: str | Path) -> None:
    """A recording that cannot be written is refused before the episodes run, not after them."""
    if Path(path).suffix.lower() not in VIDEO_FORMATS:
        raise VisualEnvError(f"cannot record {path}: expected a file ending in {' or '.join(VIDEO_FORMATS)}")
    make_dir(Path(path).parent)


def play(spec: str, *, model_path: str | None = None, algo: str = "ppo", episodes: int = 3, seed: int = 0,
         record: str | None = None, fps: int = 15, max_frames: int = 2000, view_preset: str | None = None,
         view_size: int | None = None) -> list[Episode]:
    """Play `episodes`; with `record`, save a GIF/MP4 of the view beside the agent's observation."""
    if record:
        check_recording(record)
    model = load_model(model_path, algo) if model_path else None
    env = _play_env(spec, model, model_path, view_preset, view_size)
    env.action_space.seed(seed)
    frames: list[np.ndarray] | None = [] if record else None
    try:
        results = [_play_episode(env, model, seed + episode, frames, max_frames) for episode in range(episodes)]
    finally:
        env.close()
    if record and frames:
        save_video(frames, record, fps)
    return results


def _play_env(spec: str, model: Any, model_path: str | None, view_preset: str | None, view_size: int | None) -> Any:
    """The env with the recorded view's settings, its frames stacked as the model was trained."""
    from visualenv.env import VisualEnv
    from visualenv.registration import resolve
    from visualenv.spec import load_spec

    loaded = with_view(load_spec(resolve(spec)), preset=view_preset, size=view_size)
    env: Any = VisualEnv(loaded, render_mode="rgb_array")
    if model is None:
        return env
    try:
        return stacked_like(env, model, str(model_path))
    except BaseException:
        env.close()
        raise


def _play_episode(env: Any, model: Any, seed: int, frames: list[np.ndarray] | None, max_frames: int) -> Episode:
    """One episode from a reset seeded `seed`: the model's deterministic actions (random ones without a model).

    With `frames`, each step's observation beside the view is appended, up to `max_frames` in all."""
    from visualenv.wrappers import FrameStack

    obs, info = env.reset(seed=seed)
    ret, length = 0.0, 0
    while True:
        if frames is not None and len(frames) < max_frames:
            latest = env.latest if isinstance(env, FrameStack) else obs
            frames.append(side_by_side(latest, env.render()))
        action = model.predict(obs, deterministic=True)[0] if model is not None else env.action_space.sample()
        obs, reward, terminated, truncated, info = env.step(action)
        ret += float(reward)
        length += 1
        if terminated or truncated:
            return Episode(ret, length, bool(info.get("is_success")), info.get("outcome"))


def load_model(model_path: str, algo: str = "ppo") -> Any:
    """An SB3 model (.zip), or the policy of an RLlib checkpoint folder (`train --backend rllib`); both have ``predict``."""
    if Path(model_path).is_dir():
        try:
            from visualenv.rllib import RLlibPolicy, is_checkpoint
        except ImportError as exc:
            raise VisualEnvError(f"{model_path} is a folder: an RLlib checkpoint needs Ray RLlib (pip install 'visualenv[ray]'; {exc})") from None
        if not is_checkpoint(model_path):
            raise VisualEnvError(f"{model_path} is not a checkpoint of `visualenv train --backend rllib` (no {Path('learner_group', 'learner', 'rl_module')})")
        try:
            return RLlibPolicy.load(model_path)
        except Exception as exc:  # RLlib raises whatever its unpickling met
            raise VisualEnvError(f"cannot load {model_path} as an RLlib checkpoint: {exc}") from None
    from visualenv.training import algorithm_class

    try:
        return algorithm_class(algo).load(model_path, device="cpu")
    except Exception as exc:  # SB3 raises whatever its unpickling met: report it, whatever it is
        raise VisualEnvError(f"cannot load {model_path} as a {algo.upper()} model: {exc}") from None


def stacked_like(env: Any, model: Any, model_path: str) -> Any:
    """`env` with the frame stack the model was trained on; a model of another env is an error, not a crash mid-episode."""
    from visualenv.wrappers import FrameStack

    want, have = model.observation_space, env.observation_space
    depth = next((w // h for w, h in _channel_pairs(want, have) if w != h and w % h == 0), 1)
    if depth > 1:
        env = FrameStack(env, depth)
    actions, ours = model.action_space, env.action_space
    if not _fits(want, env.observation_space) or type(actions) is not type(ours) or actions.shape != ours.shape \
            or getattr(actions, "n", None) != getattr(ours, "n", None):
        raise VisualEnvError(f"{model_path} was trained on observations {_shapes(want)} and actions {actions}; "
                             f"this env has observations {_shapes(env.observation_space)} and actions {ours}")
    return env


def _channel_pairs(want: Any, have: Any) -> list[tuple[int, int]]:
    """(model's channels, env's channels) of each image both have: their ratio is the frame stack."""
    from stable_baselines3.common.preprocessing import is_image_space_channels_first

    ours = subspaces(have)
    pairs = []
    for key, w in subspaces(want).items():
        h = ours.get(key)
        if h is not None and len(w.shape or ()) == 3 and len(h.shape or ()) == 3:
            pairs.append((w.shape[0] if is_image_space_channels_first(w) else w.shape[-1], h.shape[-1]))  # type: ignore[arg-type,index]
    return pairs


def _fits(want: Any, have: Any) -> bool:
    """Same keys and shapes; SB3 also takes channel-last images for a channel-first model."""
    w, h = subspaces(want), subspaces(have)
    return w.keys() == h.keys() and all(
        w[k].shape is not None and h[k].shape is not None and w[k].shape in (h[k].shape, h[k].shape[-1:] + h[k].shape[:-1]) for k in w)  # type: ignore[index]


def _shapes(space: Any) -> Any:
    by_key = subspaces(space)
    return by_key[""].shape if list(by_key) == [""] else {k: s.shape for k, s in by_key.items()}


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
