"""The suite's video backgrounds without rendering (visualenv/render/videos.py): its lists and levels, its ping-pong,
the draw from the distractions' generator, and the frames read as untrusted files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.fixtures.hostile_files import png_header
from visualenv.errors import VisualEnvError
from visualenv.render.distractions import EpisodeDistractions, draw
from visualenv.render.plan import Distractions, VideoBackground
from visualenv.render.videos import (
    DAVIS17_TRAINING_VIDEOS,
    DAVIS17_VALIDATION_VIDEOS,
    load_frame,
    ping_pong,
    video_library,
    videos_at,
)


def test_the_suites_lists_and_its_videos_per_level() -> None:
    assert len(DAVIS17_TRAINING_VIDEOS) == 60 and len(DAVIS17_VALIDATION_VIDEOS) == 30
    assert not set(DAVIS17_TRAINING_VIDEOS) & set(DAVIS17_VALIDATION_VIDEOS)
    assert videos_at(0.1, "train") == ("bear", "bmx-bumps", "boat", "boxing-fisheye")
    assert [len(videos_at(d, "train")) for d in (0.05, 0.1, 0.15, 0.2, 0.3, 1.0)] == [4, 4, 8, 8, 60, 60]
    assert [len(videos_at(d, "val")) for d in (0.1, 0.2, 0.3)] == [4, 8, 30]


def test_ping_pong_turns_at_both_ends_as_the_suite_does() -> None:
    """From frame 1 forward over 3 frames: the last is shown twice as the video turns, the first once."""
    frame, step, played = 1, 1, []
    for _ in range(8):
        frame, step = ping_pong(frame, step, 3)
        played.append(frame)
    assert played == [2, 2, 1, 0, 1, 2, 2, 1]
    assert ping_pong(0, -1, 3) == (0, 1) and ping_pong(0, 1, 1) == (0, -1)


def davis(root: Path, names: tuple[str, ...], frames: int = 2) -> Path:
    for name in names:
        (root / name).mkdir(parents=True)
        for f in range(frames):
            Image.new("RGB", (16, 8), (10 * f, 0, 0)).save(root / name / f"{f:05d}.jpg")
    return root


def test_a_video_and_frame_are_drawn_from_the_distractions_generator(tmp_path: Path) -> None:
    """The same generator state draws the same video and frame; the other kinds' numbers are those drawn without
    videos (the video is drawn last); a dynamic episode plays its frames."""
    folder = davis(tmp_path / "davis", DAVIS17_TRAINING_VIDEOS[:4], frames=5)
    settings = Distractions(0.1, True, True, VideoBackground(str(folder), "train"), True)
    plain = Distractions(0.1, True, True, True, True)
    drawn = [draw(settings, np.random.default_rng(seed)) for seed in range(12)]
    again = [draw(settings, np.random.default_rng(seed)) for seed in range(12)]
    assert drawn == again and len({d.video for d in drawn}) > 1 and len({d.frame for d in drawn}) > 1
    assert all(Path(d.video_frame).parent.name == DAVIS17_TRAINING_VIDEOS[d.video] for d in drawn)
    without = draw(plain, np.random.default_rng(0))
    assert (without.yaw, without.colors_seed, without.background_seed) == (
        drawn[0].yaw,
        drawn[0].colors_seed,
        drawn[0].background_seed,
    )
    episode = EpisodeDistractions(settings)
    episode.rng, episode.current = np.random.default_rng(0), drawn[0]
    frames = [drawn[0].frame]
    for _ in range(10):
        episode.advance()
        frames.append(episode.current.frame)
    assert set(np.abs(np.diff(frames))) <= {0, 1} and {0, 4} <= set(frames)


def test_a_frame_is_read_as_untrusted_input(tmp_path: Path) -> None:
    """Its size is checked from its header before it is read; a file that is not an image is named."""
    bomb = png_header(tmp_path / "bomb.png", 30_000, 30_000)
    with pytest.raises(VisualEnvError, match=r"distractions.background.videos: .*bomb.png is 30000 x 30000 pixels"):
        load_frame(str(bomb))
    junk = tmp_path / "junk.jpg"
    junk.write_bytes(b"\xff\xd8 not a jpeg at all")
    with pytest.raises(VisualEnvError, match=r"distractions.background.videos: .*junk.jpg"):
        load_frame(str(junk))
    frame = davis(tmp_path / "ok", ("bear",), frames=1) / "bear" / "00000.jpg"
    assert load_frame(str(frame), 32).shape == (32, 32, 3)


def test_a_folder_without_the_levels_videos_names_them(tmp_path: Path) -> None:
    folder = davis(tmp_path / "davis", DAVIS17_TRAINING_VIDEOS[:3])
    (folder / "boxing-fisheye").mkdir()  # a video without frames is missing too
    with pytest.raises(VisualEnvError, match=r"lacks 1 of the 4 videos the train split .*: boxing-fisheye$"):
        video_library(str(folder), "train", 0.1)
    with pytest.raises(VisualEnvError, match=r"no folder .*elsewhere"):
        video_library(str(tmp_path / "elsewhere"), "train", 0.1)


def test_split_all_takes_any_folder_of_clips_in_name_order(tmp_path: Path) -> None:
    """`split: all`: every subfolder holding frames is a clip, in name order, the level taking the first 4, 8 or all;
    a folder without one is a located error."""
    names = tuple(f"clip-{i:02d}" for i in range(10))
    folder = davis(tmp_path / "clips", names[::-1])
    (folder / "notes").mkdir()  # no frames: not a clip
    assert video_library(str(folder), "all", 0.1).names == names[:4]
    assert video_library(str(folder), "all", 0.2).names == names[:8]
    assert video_library(str(folder), "all", 0.3).names == names
    ranged = Distractions((0.0, 0.3), True, True, VideoBackground(str(folder), "all"), False)
    assert {draw(ranged, np.random.default_rng(seed)).video for seed in range(200)} == set(range(10))
    (tmp_path / "empty").mkdir()
    with pytest.raises(VisualEnvError, match="holds no clip"):
        video_library(str(tmp_path / "empty"), "all", 0.1)
