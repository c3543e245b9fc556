"""Video backgrounds as the Distracting Control Suite plays them: DAVIS 2017 clips from a folder the user points at.

The suite (Stone et al., 2021; its ``background.py`` and ``suite_utils.py``) draws a video per episode from the first 4,
8 or all of DAVIS 2017's training videos by level (easy, medium, hard), or of the 30 it holds out for validation, and
shows it over the sky fully opaque: one frame per episode, or, when dynamic, a frame per step played forward and
back. DAVIS is not ours to ship: a :class:`VideoLibrary` reads the user's copy (``DAVIS/JPEGImages/480p``: a folder
per video, a JPEG per frame), checking that the videos the level needs are there, and every frame's size from its
header before it is read (:func:`visualenv.files.check_image`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from visualenv.errors import VisualEnvError
from visualenv.files import MAX_IMAGE_PIXELS, FileSizeError, check_image

#: DAVIS 2017's training videos, in the suite's order (``DAVIS17_TRAINING_VIDEOS``): a level takes the first few
DAVIS17_TRAINING_VIDEOS = (
    *("bear", "bmx-bumps", "boat", "boxing-fisheye", "breakdance-flare", "bus", "car-turn", "cat-girl"),
    *("classic-car", "color-run", "crossing", "dance-jump", "dancing", "disc-jockey", "dog-agility", "dog-gooses"),
    *("dogs-scale", "drift-turn", "drone", "elephant", "flamingo", "hike", "hockey", "horsejump-low", "kid-football"),
    *("kite-walk", "koala", "lady-running", "lindy-hop", "longboard", "lucia", "mallard-fly", "mallard-water"),
    *("miami-surf", "motocross-bumps", "motorbike", "night-race", "paragliding", "planes-water", "rallye", "rhino"),
    *("rollerblade", "schoolgirls", "scooter-board", "scooter-gray", "sheep", "skate-park", "snowboard"),
    *("soccerball", "stroller", "stunt", "surf", "swing", "tennis", "tractor-sand", "train", "tuk-tuk"),
    *("upside-down", "varanus-cage", "walking"),
)
#: the videos the suite holds out for validation (``DAVIS17_VALIDATION_VIDEOS``)
DAVIS17_VALIDATION_VIDEOS = (
    *("bike-packing", "blackswan", "bmx-trees", "breakdance", "camel", "car-roundabout", "car-shadow", "cows"),
    *("dance-twirl", "dog", "dogs-jump", "drift-chicane", "drift-straight", "goat", "gold-fish", "horsejump-high"),
    *("india", "judo", "kite-surf", "lab-coat", "libby", "loading", "mbike-trick", "motocross-jump"),
    *("paragliding-launch", "parkour", "pigs", "scooter-black", "shooting", "soapbox"),
)
SPLITS = {"train": DAVIS17_TRAINING_VIDEOS, "val": DAVIS17_VALIDATION_VIDEOS}
#: how many of a split's videos each of the suite's levels plays (``DIFFICULTY_NUM_VIDEOS``; hard: all)
LEVEL_VIDEOS = ((0.1, 4), (0.2, 8))
#: the files read as frames, in name order
FRAME_SUFFIXES = (".jpg", ".jpeg", ".png")
#: a frame's side once resized (the suite resizes every frame to its 800 x 800 sky texture; an 84 x 84 view of a face
#: needs far fewer)
FRAME_SIDE = 256
#: where a bad folder is reported
FIELD = "distractions.background.videos"


class VideoFolderError(VisualEnvError):
    """A folder of videos that is missing or lacks the level's videos, or a frame that cannot be read: the env
    reports it at the field that names the folder (the spec's line, or make()'s option)."""

    def __init__(self, detail: str) -> None:
        super().__init__(f"{FIELD}: {detail}")
        #: the problem without the field's name
        self.detail = detail


def videos_at(difficulty: float, split: str, clips: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The videos the suite plays at `difficulty`: the first 4 of the split up to its easy level (0.1), 8 up to its
    medium (0.2), every one above. The split ``all`` is `clips`, a folder's every clip by name."""
    names = clips if split == "all" else SPLITS[split]
    for level, count in LEVEL_VIDEOS:
        if difficulty <= level + 1e-9:
            return names[:count]
    return names


@dataclass(frozen=True)
class VideoLibrary:
    """The videos of a level in the user's folder: each one's frames, in name order."""

    folder: Path
    names: tuple[str, ...]
    frames: tuple[tuple[str, ...], ...]  # each video's frame files (full paths)


@functools.lru_cache(maxsize=16)
def video_library(folder: str, split: str, difficulty: float) -> VideoLibrary:
    """The library of `split`'s videos at `difficulty` under `folder`, listed once per process; an error naming what is
    missing (the folder, or the videos it lacks) otherwise."""
    root = Path(folder)
    if not root.is_dir():
        raise VideoFolderError(
            f"no folder {root} (a folder of DAVIS 2017's videos, DAVIS/JPEGImages/480p: docs/distractions.md)"
        )
    clips = tuple(sorted(d.name for d in root.iterdir() if d.is_dir() and _frames_in(d))) if split == "all" else ()
    if split == "all" and not clips:
        raise VideoFolderError(f"{root} holds no clip (a folder of .jpg or .png frames)")
    names = videos_at(difficulty, split, clips)
    frames, missing = [], []
    for name in names:
        video = root / name
        files = _frames_in(video)
        if not files:
            missing.append(name)
        frames.append(tuple(files))
    if missing:
        shown = ", ".join(missing[:8]) + (f" and {len(missing) - 8} more" if len(missing) > 8 else "")
        raise VideoFolderError(
            f"{root} lacks {len(missing)} of the {len(names)} videos the {split} split plays at this "
            f"difficulty (a folder of .jpg frames each): {shown}"
        )
    return VideoLibrary(root, names, tuple(frames))


def _frames_in(video: Path) -> list[str]:
    """A clip's frame files (full paths) in name order; none where `video` is not a folder."""
    return sorted(str(f) for f in video.iterdir() if f.suffix.lower() in FRAME_SUFFIXES) if video.is_dir() else []


@functools.lru_cache(maxsize=512)
def load_frame(path: str, side: int = FRAME_SIDE) -> np.ndarray:
    """The frame at `path` as ``(side, side, 3)`` uint8, resized as the suite resizes it to its square sky (bilinear);
    its size checked from its header before it is read."""
    from PIL import Image, UnidentifiedImageError

    try:
        check_image(Path(path), MAX_IMAGE_PIXELS, "nothing but a smaller frame")
        with Image.open(path) as image:
            rgb = image.convert("RGB").resize((side, side), Image.Resampling.BILINEAR)
            return np.asarray(rgb, dtype=np.uint8)
    except FileSizeError as exc:
        raise VideoFolderError(str(exc)) from None
    except (OSError, UnidentifiedImageError) as exc:
        raise VideoFolderError(f"cannot read the frame {path}: {exc}") from None


def ping_pong(frame: int, step: int, count: int) -> tuple[int, int]:
    """A dynamic video one step on, as the suite plays it: `frame` moves by `step` (±1); past the first frame it turns
    forward, at or past the last it stays there and turns back."""
    frame += step
    if frame <= 0:
        frame, step = 0, abs(step)
    if frame >= count:
        frame, step = count - 1, -abs(step)
    return frame, step
