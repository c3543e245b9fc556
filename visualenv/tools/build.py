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
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from PIL import Image
from tqdm import tqdm

from visualenv.files import make_dir
from visualenv.render.images import ascii_art, side_by_side
from visualenv.env.registration import resolve
from visualenv.versions import versions


@dataclass
class BuildResult:
    env_id: str
    folder: Path
    seconds: float
    summary: list[str] = field(default_factory=list)
    ascii_preview: str = ""
    #: what the text sketch shows, e.g. "RGB shown as grayscale text" (the colours are in preview.png)
    ascii_note: str = ""


def build_env(
    spec: str | Path,
    out_dir: str | Path = "build",
    *,
    seed: int = 0,
    device: str | None = None,
    trust_code: bool = False,
) -> BuildResult:
    from visualenv.env import VisualEnv
    from visualenv.spec.loader import load_spec

    start = time.perf_counter()
    source = resolve(spec)
    loaded = load_spec(source)
    options: dict[str, Any] = {"device": device} if device else {}
    env = VisualEnv(loaded, render_mode="rgb_array", renderer_options=options or None, trust_code=trust_code)
    out_root = make_dir(Path(out_dir))
    final = out_root / loaded.spec.id
    tmp = Path(tempfile.mkdtemp(prefix=f".{loaded.spec.id}.", dir=out_root))
    try:
        obs, _ = env.reset(seed=seed)
        view = env.render()
        assert view is not None
        Image.fromarray(side_by_side(obs, view)).save(tmp / "preview.png")
        from visualenv.render.blender.scene.export import save_blend

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
    return BuildResult(loaded.spec.id, final, time.perf_counter() - start, summary, ascii_art(first), _sketch_note(obs))


def _sketch_note(obs: Any) -> str:
    """What the terminal sketch of `obs` leaves out: the colours of an RGB image, the other cameras."""
    first = obs if not isinstance(obs, dict) else next(iter(obs.values()))
    notes = []
    if isinstance(obs, dict) and len(obs) > 1:
        notes.append(f"camera '{next(iter(obs))}' of {len(obs)}")
    if first.shape[2] >= 3:
        notes.append("RGB shown as grayscale text; the colours are in preview.png")
    return "; ".join(notes)


def _swap_in(tmp: Path, final: Path) -> None:
    old = None
    if final.exists():
        old = final.with_name(final.name + ".old")
        shutil.rmtree(old, ignore_errors=True)
        final.rename(old)
    tmp.rename(final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def preview_frames(
    spec: str | Path,
    out_dir: str | Path,
    *,
    steps: int = 20,
    seed: int = 0,
    progress: bool = False,
    trust_code: bool = False,
) -> list[Path]:
    """Frames of a random-action episode (observation beside the view), as PNGs; `progress` shows a bar on stderr
    (each frame is two renders, the high-resolution view a slow one)."""
    from visualenv.env import VisualEnv
    from visualenv.spec.loader import load_spec

    loaded = load_spec(resolve(spec))
    env = VisualEnv(loaded, render_mode="rgb_array", trust_code=trust_code)
    out = make_dir(Path(out_dir))
    paths = []
    bar = tqdm(total=steps + 1, desc="preview", unit="frame", disable=not progress, file=sys.stderr)
    try:
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        for i in range(steps + 1):
            path = out / f"frame_{i:04d}.png"
            Image.fromarray(side_by_side(obs, env.render())).save(path)  # type: ignore[arg-type]
            paths.append(path)
            bar.update()
            if i == steps:
                break
            obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                obs, _ = env.reset()
    finally:
        bar.close()
        env.close()
    return paths
