"""`visualenv build` and `visualenv preview`: compile a spec into a build folder.

A build folder holds env.json (the validated spec, versions and a hash),
scene.blend (the assembled scene, for Blender's GUI) and preview.png (the
agent's observation beside the high-resolution view). It is written to a
temporary folder first and swapped in only when everything succeeded, so a
failed build never destroys an earlier one.
"""

from __future__ import annotations

import hashlib
import json
import platform
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from visualenv.errors import VisualEnvError
from visualenv.registration import resolve

ASCII_RAMP = " .:-=+*#%@"


@dataclass
class BuildResult:
    env_id: str
    folder: Path
    seconds: float
    summary: list[str] = field(default_factory=list)
    ascii_preview: str = ""


def versions() -> dict[str, str]:
    import gymnasium

    import visualenv

    out = {"visualenv": visualenv.__version__, "gymnasium": gymnasium.__version__, "numpy": np.__version__, "python": platform.python_version()}
    try:
        import bpy

        out["blender"] = bpy.app.version_string
    except ImportError:  # pragma: no cover - bpy is a dependency
        pass
    return out


def build_env(spec: str | Path, out_dir: str | Path = "build", *, seed: int = 0, device: str | None = None) -> BuildResult:
    from visualenv.env import VisualEnv
    from visualenv.spec.loader import load_spec

    start = time.perf_counter()
    source = resolve(spec)
    loaded = load_spec(source)
    options: dict[str, Any] = {"device": device} if device else {}
    out_root = make_dir(Path(out_dir))
    env = VisualEnv(loaded, render_mode="rgb_array", renderer_options=options or None)
    final = out_root / loaded.spec.id
    tmp = Path(tempfile.mkdtemp(prefix=f".{loaded.spec.id}.", dir=out_root))
    try:
        obs, _ = env.reset(seed=seed)
        view = env.render()
        assert view is not None
        Image.fromarray(side_by_side(obs, view)).save(tmp / "preview.png")
        from visualenv.render.blender.export import save_blend

        save_blend(env.renderer.scene, tmp / "scene.blend")  # type: ignore[attr-defined]
        text = Path(source).read_bytes()
        record = {
            "id": loaded.spec.id,
            "source": str(Path(source).resolve()),
            "sha256": hashlib.sha256(text).hexdigest(),
            "versions": versions(),
            "observation_space": str(env.observation_space),
            "action_space": str(env.action_space),
            "spec": loaded.spec.model_dump(mode="json"),
        }
        (tmp / "env.json").write_text(json.dumps(record, indent=2) + "\n")
        _swap_in(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        env.close()
    summary = [
        f"observation: {env.observation_space}",
        f"actions:     {env.action_space}",
        "files:       env.json, scene.blend, preview.png",
    ]
    first = obs if not isinstance(obs, dict) else next(iter(obs.values()))
    return BuildResult(loaded.spec.id, final, time.perf_counter() - start, summary, ascii_art(first))


def _swap_in(tmp: Path, final: Path) -> None:
    old = None
    if final.exists():
        old = final.with_name(final.name + ".old")
        shutil.rmtree(old, ignore_errors=True)
        final.rename(old)
    tmp.rename(final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def to_rgb(image: np.ndarray) -> np.ndarray:
    return np.repeat(image, 3, axis=2) if image.shape[2] == 1 else image[..., :3]


def side_by_side(observation: Any, view: np.ndarray) -> np.ndarray:
    """Observation(s), scaled up (nearest) to the view's height, left of the view."""
    images = list(observation.values()) if isinstance(observation, dict) else [observation]
    height = view.shape[0]
    panels = []
    for image in images:
        scale = max(1, height // image.shape[0])
        big = np.kron(to_rgb(image), np.ones((scale, scale, 1), dtype=np.uint8))
        pad = np.zeros((height, big.shape[1], 3), np.uint8)
        pad[: min(height, big.shape[0])] = big[:height]
        panels.append(pad)
    gap = np.full((height, 4, 3), 255, np.uint8)
    parts = []
    for panel in panels + [view[..., :3]]:
        parts += [panel, gap]
    return np.concatenate(parts[:-1], axis=1)


def ascii_art(image: np.ndarray, width: int = 50) -> str:
    """A terminal sketch of an image (characters are about twice as tall as wide)."""
    gray = image.astype(np.float32).mean(axis=2)
    h, w = gray.shape
    rows = max(1, int(h * width / w / 2))
    ys = (np.arange(rows) * h / rows).astype(int)
    xs = (np.arange(width) * w / width).astype(int)
    small = gray[np.ix_(ys, xs)]
    idx = (small / 256 * len(ASCII_RAMP)).astype(int).clip(0, len(ASCII_RAMP) - 1)
    return "\n".join("".join(ASCII_RAMP[i] for i in row) for row in idx)


def make_dir(path: Path) -> Path:
    """``mkdir -p`` that reports a folder it cannot make as a user error, before any work is done."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise VisualEnvError(f"cannot create the folder {path}: {exc.strerror or exc}") from None
    return path


def preview_frames(spec: str | Path, out_dir: str | Path, *, steps: int = 20, seed: int = 0) -> list[Path]:
    """Frames of a random-action episode (observation beside the view), as PNGs."""
    from visualenv.env import VisualEnv
    from visualenv.spec.loader import load_spec

    loaded = load_spec(resolve(spec))
    out = make_dir(Path(out_dir))
    env = VisualEnv(loaded, render_mode="rgb_array")
    paths = []
    try:
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        for i in range(steps + 1):
            path = out / f"frame_{i:04d}.png"
            Image.fromarray(side_by_side(obs, env.render())).save(path)  # type: ignore[arg-type]
            paths.append(path)
            if i == steps:
                break
            obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                obs, _ = env.reset()
    finally:
        env.close()
    return paths
