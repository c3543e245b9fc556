"""`visualenv play`: run episodes with a random or trained policy and record them."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from visualenv.files import make_dir
from visualenv.render.images import side_by_side
from visualenv.errors import VisualEnvError
from visualenv.env.wrappers import FrameStack
from visualenv.train.model_files import load_model, stacked_like
from visualenv.compat import mkl
from visualenv.train.reproducible import pinned_inference

VIDEO_FORMATS = (".gif", ".webp", ".mp4")
WEBP_QUALITY = 70  # lossy animated WebP: a few hundred kB where a GIF of path-traced frames takes megabytes


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


def play(
    spec: str,
    *,
    model_path: str | None = None,
    algo: str = "ppo",
    episodes: int = 3,
    seed: int = 0,
    record: str | None = None,
    fps: int = 15,
    max_frames: int = 2000,
    view_preset: str | None = None,
    view_size: int | None = None,
    trust_pickle: bool = False,
    trust_code: bool = False,
) -> list[Episode]:
    """Play `episodes`; with `record`, save a GIF/MP4 of the view beside the agent's observation.

    `trust_pickle`: a pickle-based model may load (:func:`~visualenv.train.model_files.load_model`).
    `trust_code`: the spec's ``dynamics.python`` module may be imported (docs/security.md)."""
    if record:
        check_recording(record)
    mkl.pin()  # before the model is built (its initialisation calls MKL): the actions eval's episodes had
    model = load_model(model_path, algo, trust_pickle=trust_pickle) if model_path else None
    env = _play_env(spec, model, model_path, view_preset, view_size, trust_code)
    env.action_space.seed(seed)
    frames: list[np.ndarray] | None = [] if record else None
    try:
        with pinned_inference():
            results = [_play_episode(env, model, seed + episode, frames, max_frames) for episode in range(episodes)]
    finally:
        env.close()
    if record and frames:
        save_video(frames, record, fps)
    return results


def _play_env(
    spec: str,
    model: Any,
    model_path: str | None,
    view_preset: str | None,
    view_size: int | None,
    trust_code: bool = False,
) -> Any:
    """The env with the recorded view's settings, its frames stacked as the model was trained."""
    from visualenv.env import VisualEnv
    from visualenv.env.registration import resolve
    from visualenv.spec import load_spec

    loaded = with_view(load_spec(resolve(spec)), preset=view_preset, size=view_size)
    env: Any = VisualEnv(loaded, render_mode="rgb_array", trust_code=trust_code)
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


def save_video(frames: list[np.ndarray], path: str | Path, fps: int) -> Path:
    """GIF, animated WebP or MP4 by the file's extension (imageio; WebP through Pillow)."""
    import imageio.v3 as iio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    suffix = path.suffix.lower()
    if suffix == ".gif":
        iio.imwrite(path, np.stack(frames), duration=1000 / fps, loop=0)
    elif suffix == ".webp":
        iio.imwrite(
            path,
            np.stack(frames),
            plugin="pillow",
            extension=".webp",
            duration=round(1000 / fps),
            loop=0,
            quality=WEBP_QUALITY,
            method=4,
        )
    else:
        iio.imwrite(path, np.stack(frames), fps=fps, codec="libx264", macro_block_size=1)
    return path
