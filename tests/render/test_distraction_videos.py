"""The Distracting Control Suite's video backgrounds (docs/distractions.md), rendered with real Blender.

A tiny DAVIS 2017 folder is generated per test (the suite's video names, a few solid-colour JPEG frames each, every
frame's colour its own): the sky's pixels show the episode's frame as its bytes, every other pixel is the plain
env's, a seed draws the same video and frame again, a dynamic episode plays a frame per step and turns at the ends,
a batch shows each env's own video, and a missing folder or video is an error that names it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import visualenv
from visualenv.errors import SpecError, VisualEnvError
from visualenv.render.videos import DAVIS17_TRAINING_VIDEOS, DAVIS17_VALIDATION_VIDEOS

from tests.render.test_distractions import segmented_cartpole

pytestmark = pytest.mark.blender
bpy = pytest.importorskip("bpy")

#: every kind but the background off (the floor opaque), at the suite's easy level: its first 4 videos
BACKGROUND_ONLY = {"difficulty": 0.1, "camera": False, "colors": False, "floor_alpha": 1.0}


def davis_folder(root: Path, names: tuple[str, ...], frames: int = 3) -> Path:
    """DAVIS 2017's layout (a folder of JPEG frames per video), each frame one colour of its own."""
    for v, name in enumerate(names):
        (root / name).mkdir(parents=True)
        for f in range(frames):
            Image.new("RGB", (40, 24), frame_color(v, f)).save(root / name / f"{f:05d}.jpg", quality=95)
    return root


def frame_color(video: int, frame: int) -> tuple[int, int, int]:
    return (30 + 50 * video, 220 - 60 * frame, 40 + 50 * frame)


def shown(frame_file: str) -> np.ndarray:
    """The colour of a generated frame, as its JPEG decodes."""
    return np.asarray(Image.open(frame_file).convert("RGB"), dtype=int)[0, 0]


def test_the_sky_shows_the_episodes_frame_and_nothing_else_changes(tmp_path: Path) -> None:
    """Opaque: every sky pixel is the frame's colour (within 2 levels); every other pixel, the segmentation, the
    rewards and the state are the plain env's; the same seed draws the same video and frame."""
    videos = davis_folder(tmp_path / "davis", DAVIS17_TRAINING_VIDEOS[:4])
    spec = segmented_cartpole(tmp_path)
    plain = visualenv.make(spec)
    env = visualenv.make(spec, distractions={**BACKGROUND_ONLY, "background": {"videos": str(videos)}})
    try:
        drawn: dict[int, list] = {}
        for seed in (5, 6, 7, 5):
            clean, _ = plain.reset(seed=seed)
            obs, _ = env.reset(seed=seed)
            current = env.unwrapped._distractions.current
            drawn.setdefault(seed, []).append((current.video_frame, obs["eye"].tobytes()))
            sky = obs["mask"][..., 0] == 0
            assert sky.mean() > 0.2 and np.array_equal(obs["mask"], clean["mask"])
            assert np.abs(obs["eye"][sky].astype(int) - shown(current.video_frame)).max() <= 2
            assert np.array_equal(obs["eye"][~sky], clean["eye"][~sky])  # the frame lights nothing
        assert drawn[5][0] == drawn[5][1]  # the same seed: the same video, frame and pixels
        assert len({frames[0][0] for frames in drawn.values()}) > 1
        plain.reset(seed=5)
        env.reset(seed=5)
        for action in np.random.default_rng(0).uniform(-1, 1, size=(3, 1)).astype(np.float32):
            assert plain.step(action)[1:4] == env.step(action)[1:4]
            assert np.array_equal(plain.unwrapped.data.qpos, env.unwrapped.data.qpos)
    finally:
        plain.close()
        env.close()


def test_a_dynamic_video_plays_a_frame_a_step_forward_and_back(tmp_path: Path) -> None:
    """The suite's ping-pong: a frame per step, turning at the first and the last frame; the sky shows each."""
    videos = davis_folder(tmp_path / "davis", DAVIS17_TRAINING_VIDEOS[:4])
    settings = {**BACKGROUND_ONLY, "dynamic": True, "background": {"videos": str(videos)}}
    env = visualenv.make(segmented_cartpole(tmp_path), distractions=settings)
    images = len(bpy.data.images)
    try:
        obs, _ = env.reset(seed=3)
        played, colors = [], []
        for _ in range(8):
            current = env.unwrapped._distractions.current
            sky = obs["mask"][..., 0] == 0
            assert np.abs(obs["eye"][sky].astype(int) - shown(current.video_frame)).max() <= 2
            played.append(current.frame)
            colors.append(tuple(obs["eye"][sky][0]))
            obs = env.step(np.zeros(1, np.float32))[0]
        steps = np.diff(played)
        assert set(np.abs(steps)) <= {0, 1} and {-1, 1} <= set(steps)  # forward and back
        assert 0 in played and 2 in played and len(set(colors)) == 3  # every frame of the 3, each seen
    finally:
        env.close()
    assert len(bpy.data.images) == images  # every frame's image removed with the renderer


def test_a_long_dynamic_episode_shows_every_frame_as_drawn(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A new frame's image never shows an older one's pixels (Cycles knows an image by its address, and a removed
    image's address comes back: a few frames in a hundred were stale), and letting Cycles' session go (every few
    frames here) renders the same frames; the frames' images alive stay within the bound, and the renderer's list of
    datablocks lets the removed ones go."""
    from visualenv.render.blender.look import video_backdrop

    videos = davis_folder(tmp_path / "davis", DAVIS17_TRAINING_VIDEOS[:4], frames=20)
    settings = {**BACKGROUND_ONLY, "dynamic": True, "background": {"videos": str(videos)}}
    before = len(bpy.data.images)

    def episode(steps: int) -> tuple[list[bytes], int, int]:
        """The episode's frames, the most images alive at once and the renderer's list's length at the end."""
        env = visualenv.make(segmented_cartpole(tmp_path), distractions=settings)
        try:
            obs, _ = env.reset(seed=1)
            frames, most = [], 0
            for step in range(steps):
                sky = obs["mask"][..., 0] == 0
                want = shown(env.unwrapped._distractions.current.video_frame)
                off = np.abs(obs["eye"][sky].astype(int) - want).max()
                assert off <= 2, (
                    f"step {step}: the sky is {obs['eye'][sky][0]} where the frame is {want} (the whole frame black: "
                    f"{not obs['eye'].any()}; {len(bpy.data.images)} images alive)"
                )
                frames.append(obs["eye"].tobytes())
                most = max(most, sum(" videos" in image.name for image in bpy.data.images))  # the atlas's
                obs = env.step(np.zeros(1, np.float32))[0]
            return frames, most, len(env.unwrapped._renderer._ids)
        finally:
            env.close()

    kept, most, _ = episode(120)
    # every frame's image kept while the session lives (and the one read when it was last let go)
    assert 100 < most <= video_backdrop.RETAINED_IMAGES + 1
    monkeypatch.setattr(video_backdrop, "RETAINED_IMAGES", 4)
    frames, most, listed = episode(40)
    assert frames == kept[:40]
    assert most <= 4 + 1 and listed < 100  # the images removed when the session was let go, and let go by the list
    assert len(bpy.data.images) == before  # and every one removed with the renderer


def test_a_batch_shows_each_envs_own_video(tmp_path: Path) -> None:
    """Each tile's sky is its env's frame (each env draws from its own seed, as alone), over two steps of a dynamic
    episode; the envs' videos or frames differ."""
    videos = davis_folder(tmp_path / "davis", DAVIS17_TRAINING_VIDEOS[:4])
    settings = {**BACKGROUND_ONLY, "dynamic": True, "background": {"videos": str(videos)}}
    n = 3
    batch = visualenv.make_vec(segmented_cartpole(tmp_path), n, batched=True, distractions=settings)
    try:
        tiles, _ = batch.reset(seed=11)
        for _ in range(2):
            files = [batch.unwrapped._distractions[k].current.video_frame for k in range(n)]
            for k in range(n):
                sky = tiles["mask"][k][..., 0] == 0
                assert np.abs(tiles["eye"][k][sky].astype(int) - shown(files[k])).max() <= 2, k
            tiles = batch.step(np.zeros((n, 1), np.float32))[0]
        assert len(set(files)) > 1
    finally:
        batch.close()


def test_the_split_and_the_level_pick_the_videos_and_a_missing_one_is_named(tmp_path: Path) -> None:
    """The validation split plays its own videos (the folder written in the spec relative to its own); a folder
    without the level's videos, or no folder, is an error that names what is missing (before any render)."""
    val = davis_folder(tmp_path / "val", DAVIS17_VALIDATION_VIDEOS[:4], frames=1)
    spec = segmented_cartpole(tmp_path, {**BACKGROUND_ONLY, "background": {"videos": "val", "split": "val"}})
    env = visualenv.make(spec)
    try:
        obs, _ = env.reset(seed=0)
        assert Path(env.unwrapped._distractions.current.video_frame).parent.name in DAVIS17_VALIDATION_VIDEOS[:4]
        sky = obs["mask"][..., 0] == 0
        assert np.abs(obs["eye"][sky].astype(int) - shown(env.unwrapped._distractions.current.video_frame)).max() <= 2
    finally:
        env.close()
    with pytest.raises(VisualEnvError, match=r"lacks 4 of the 4 videos the train split .*: bear, bmx-bumps, boat"):
        visualenv.make(spec, distractions={**BACKGROUND_ONLY, "background": {"videos": str(val)}})
    with pytest.raises(
        VisualEnvError, match=r"lacks 4 of the 8 videos the val split .*: camel, car-roundabout, car-shadow, cows$"
    ):
        visualenv.make(
            spec,
            distractions={**BACKGROUND_ONLY, "difficulty": 0.2, "background": {"videos": str(val), "split": "val"}},
        )
    with pytest.raises(SpecError, match=r"visualenv.make\(\): distractions.background.videos: no folder .*nowhere"):
        visualenv.make(spec, distractions={**BACKGROUND_ONLY, "background": {"videos": str(tmp_path / "nowhere")}})
    (tmp_path / "in_file").mkdir()
    located = segmented_cartpole(tmp_path / "in_file", {**BACKGROUND_ONLY, "background": {"videos": "DAVIS/480p"}})
    with pytest.raises(SpecError, match=r"cartpole_segmented.yaml:\d+:\d+: distractions.background.videos: no folder"):
        visualenv.make(located)
