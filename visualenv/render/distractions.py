"""Distractions: what one episode's observation shows changed, drawn apart from the env's own random stream.

The Distracting Control Suite (Stone et al., 2021) changes what a pixel agent sees and nothing it controls: the
camera's pose, the colours of the bodies, the floor and the sky, the background (its DAVIS videos from the user's
folder: :mod:`visualenv.render.videos`; else visualenv's own moving pattern). The camera's ranges, its
upper-hemisphere limit and the floor's alpha are the suite's (``suite_utils.py``, ``camera.py``). Here each kind is
drawn at reset from a generator of its own (:func:`distraction_generator`), so the state, the rewards and the env's
random numbers are those of the same env without distractions, and the same seed draws the same distractions.

A :class:`Distraction` is renderer-neutral numbers; a renderer applies it (Blender:
:mod:`visualenv.render.blender.look.distraction_scene`). Colours are drawn per material in the renderer's order from
``colors_seed``, so that the numbers here do not depend on how many materials a scene has.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from visualenv.render.plan import Distractions, VideoBackground
from visualenv.render.videos import VideoLibrary, ping_pong, video_library

#: the spawn key that derives the distractions' generator from the env's seed (the letters "DS")
SPAWN_KEY = 0x4453
#: a dynamic distraction's step: this share of its range at most, every env step
DRIFT = 0.05
#: a camera within this of looking straight down (radians) is not limited to the upper hemisphere by default
STRAIGHT_DOWN = math.radians(1.0)
#: how far a dynamic background plays each env step (the pattern's fourth coordinate: about 1 changes it wholly)
BACKGROUND_STEP = 0.05


@dataclass(frozen=True)
class Distraction:
    """One episode's changes (or one step's, when dynamic). Angles in radians: ``yaw`` (the azimuth, about the world's
    vertical) and ``pitch`` (the polar angle, about the horizontal axis across the view; positive lowers the camera)
    orbit it about the point it looks at (:func:`orbit`), ``roll`` turns it about its view axis; ``zoom`` scales its
    distance to that point. ``color_shift`` is the largest change of a
    colour channel; ``colors_seed`` draws each material's and the sky's shift (:func:`color_shifts`)."""

    yaw: float = 0.0
    pitch: float = 0.0  # drawn in [-reach, reach]; the orbit maps it onto the interval the limit leaves (orbit_pitch)
    roll: float = 0.0
    zoom: float = 1.0
    reach: float = 0.0  # the angles' bound, difficulty x pi/2 (0: the camera is not distracted)
    upper_hemisphere: bool | None = None  # the suite's limit (None: unless the camera looks straight down)
    floor_alpha: float = 1.0  # the opacity of a MuJoCo model's floor (its material 'grid')
    color_shift: float = 0.0
    colors_seed: int = 0
    colors_phase: float = 0.0  # a dynamic episode's drift of every colour, in [-1, 1] of color_shift
    #: the background's contrast (0: no background), the seed of its colours and pattern, and how far it has played
    background: float = 0.0
    background_seed: int = 0
    background_time: float = 0.0
    difficulty: float = 0.0  # the episode's (drawn when the settings give a range)
    #: the suite's video background (:mod:`visualenv.render.videos`): the video's index in the level's list (-1: none),
    #: the frame shown (its file, and its index), and the way a dynamic episode plays it (+1 forward, -1 back)
    video: int = -1
    video_frame: str = ""
    frame: int = 0
    frame_step: int = 1


def distraction_generator(seed_seq: np.random.SeedSequence) -> np.random.Generator:
    """The distractions' generator of an env seeded with `seed_seq`: a child of it by a key of its own, so that neither
    the env's stream nor its other children (the sensor's) move, and a reset with seed s draws the same."""
    child = np.random.SeedSequence(seed_seq.entropy, spawn_key=(*seed_seq.spawn_key, SPAWN_KEY))
    return np.random.Generator(np.random.PCG64(child))


def draw(settings: Distractions, rng: np.random.Generator) -> Distraction:
    """An episode's distraction at `settings`' difficulty, as the suite draws it: each angle uniform in
    ±difficulty·pi/2 (the pitch then mapped onto the upper hemisphere's share of that: :func:`orbit_pitch`), the zoom
    uniform in :func:`zoom_range`, the colours' seed; a range of difficulties draws the episode's first. A kind that
    is off stays as it is."""
    given = settings.difficulty
    scale = float(rng.uniform(*given)) if isinstance(given, tuple) else given  # a range's draw comes first
    reach = scale * math.pi / 2
    angles = rng.uniform(-1.0, 1.0, size=3) * reach
    zoom = 1.0 + float(rng.uniform(-0.5, 1.5)) * scale
    seed = int(rng.integers(0, 2**31 - 1))
    if not settings.camera:
        angles, zoom, reach = np.zeros(3), 1.0, 0.0
    background_seed = int(rng.integers(0, 2**31 - 1))  # drawn last: the draws before it are those of a spec without it
    video = draw_video(settings, rng, scale)
    return Distraction(
        yaw=float(angles[0]),
        pitch=float(angles[1]),
        roll=float(angles[2]),
        zoom=zoom,
        reach=reach,
        upper_hemisphere=settings.upper_hemisphere,
        floor_alpha=1.0 if settings.floor_alpha is None else settings.floor_alpha,
        color_shift=scale if settings.colors else 0.0,
        colors_seed=seed,
        background=scale if settings.background else 0.0,
        background_seed=background_seed,
        difficulty=scale,
        **video,
    )


def draw_video(settings: Distractions, rng: np.random.Generator, difficulty: float) -> dict[str, Any]:
    """The episode's video, as the suite draws it: one of the level's (at the episode's `difficulty`) uniformly, a
    frame of it uniformly and a way to play it (forward or back); nothing (and no draw) without the suite's
    backgrounds."""
    library = videos_of(settings, difficulty)
    if library is None:
        return {}
    video = int(rng.integers(len(library.names)))
    frame = int(rng.integers(len(library.frames[video])))
    step = 1 if rng.integers(2) else -1
    return {"video": video, "frame": frame, "frame_step": step, "video_frame": library.frames[video][frame]}


def videos_of(settings: Distractions, difficulty: float | None = None) -> VideoLibrary | None:
    """The videos of the level at `difficulty` (by default the largest the settings draw) in the user's folder (listed
    once per process), None without the suite's backgrounds. A lower level's list starts the higher's, so a video's
    index is the same in both."""
    videos = settings.background
    level = settings.largest if difficulty is None else difficulty
    if not isinstance(videos, VideoBackground) or level <= 0:
        return None
    return video_library(videos.videos, videos.split, level)


def drift(settings: Distraction | None, limits: Distractions, rng: np.random.Generator) -> Distraction | None:
    """A dynamic distraction one step on: every number moved by at most :data:`DRIFT` of its range, kept inside it
    (the pitch in [-reach, reach], which the orbit maps inside the limit)."""
    if settings is None:
        return None
    scale = settings.difficulty if isinstance(limits.difficulty, tuple) else limits.difficulty
    bound = scale * math.pi / 2
    step = rng.uniform(-DRIFT, DRIFT, size=5)

    def moved(value: float, change: float, low: float, high: float) -> float:
        return float(np.clip(value + change * (high - low) / 2, low, high))

    phase = moved(settings.colors_phase, step[4], -1.0, 1.0) if limits.colors else 0.0
    played = settings.background_time + (BACKGROUND_STEP if limits.background else 0.0)
    video: dict[str, Any] = {}
    library = videos_of(limits, scale)
    if library is not None and settings.video >= 0:
        frames = library.frames[settings.video]
        frame, way = ping_pong(settings.frame, settings.frame_step, len(frames))
        video = {"frame": frame, "frame_step": way, "video_frame": frames[frame]}
    if not limits.camera:
        return replace(settings, colors_phase=phase, background_time=played, **video)
    return replace(
        settings,
        **video,
        yaw=moved(settings.yaw, step[0], -bound, bound),
        pitch=moved(settings.pitch, step[1], -bound, bound),
        roll=moved(settings.roll, step[2], -bound, bound),
        zoom=moved(settings.zoom, step[3], *zoom_range(scale)),
        colors_phase=phase,
        background_time=played,
    )


def zoom_range(difficulty: float) -> tuple[float, float]:
    """The factor of the camera's distance to the point it orbits: the suite's, in by up to difficulty/2 and out by up
    to 1.5 x difficulty."""
    return 1.0 - 0.5 * difficulty, 1.0 + 1.5 * difficulty


def pitch_range(reach: float, elevation: float, limited: bool) -> tuple[float, float]:
    """The pitches a camera at `elevation` (radians above the horizontal plane through the point it orbits) may take:
    [-reach, reach], and where `limited` only those that keep it in [0, pi/2] of elevation (a positive pitch lowers
    it: its elevation becomes elevation - pitch), as the suite narrows its polar angle's interval. A camera below the
    plane, farther than `reach`, rises by `reach`."""
    if not limited:
        return -reach, reach
    low, high = max(-reach, elevation - math.pi / 2), min(reach, elevation)
    return (low, high) if low <= high else (low, low)


def is_limited(distraction: Distraction, elevation: float) -> bool:
    """Whether the camera keeps to the upper hemisphere: as the distraction says, else unless it looks straight down
    (within :data:`STRAIGHT_DOWN`: the suite does not limit reacher's camera, which does)."""
    if distraction.upper_hemisphere is not None:
        return distraction.upper_hemisphere
    return elevation < math.pi / 2 - STRAIGHT_DOWN


def orbit_pitch(distraction: Distraction, elevation: float) -> float:
    """The pitch the camera orbits by: the drawn one, uniform in [-reach, reach], mapped affinely onto
    :func:`pitch_range` (so uniform inside the narrowed interval, none piled on its bounds)."""
    reach = distraction.reach
    if reach <= 0:
        return 0.0
    low, high = pitch_range(reach, elevation, is_limited(distraction, elevation))
    return low + (distraction.pitch + reach) / (2 * reach) * (high - low)


def axis_focus(pose: np.ndarray) -> float:
    """How far along the view axis of a camera at `pose` (4x4, looking down its -Z) lies the point nearest the origin."""
    pose = np.asarray(pose, dtype=np.float64)
    forward = -pose[:3, 2] / np.linalg.norm(pose[:3, 2])
    return float(-pose[:3, 3] @ forward)


def world_up(pose: np.ndarray) -> np.ndarray:
    """The world's up (+Z) in the frame of a camera at `pose` (4x4), unit."""
    rotation = np.asarray(pose, dtype=np.float64)[:3, :3]
    rotation = rotation / np.linalg.norm(rotation, axis=0)
    return rotation.T @ np.array([0.0, 0.0, 1.0])


def elevation_of(up: np.ndarray) -> float:
    """A camera's elevation above the horizontal plane through the point ahead of it, `up` the world's up in its frame."""
    return math.asin(float(np.clip(up[2] / np.linalg.norm(up), -1.0, 1.0)))


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """4x4: a right-handed turn by `angle` about the unit `axis` (Rodrigues)."""
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    out = np.eye(4)
    out[:3, :3] = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)
    return out


def _translation(z: float) -> np.ndarray:
    out = np.eye(4)
    out[2, 3] = z
    return out


def orbit(distraction: Distraction, focus: float, up: np.ndarray) -> np.ndarray:
    """The camera's local pose (4x4, in its own frame; `up`: the world's up there) on the suite's sphere about the point
    `focus` ahead of it: turned by yaw about the world's vertical through that point (the azimuth) and by
    :func:`orbit_pitch` about the horizontal axis across its view (the polar angle, its elevation lowered by it), its
    distance times zoom, rolled about its view axis. A camera looking straight down pitches about its right axis."""
    up = np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    across = np.cross(up, [0.0, 0.0, 1.0])
    length = float(np.linalg.norm(across))
    across = across / length if length > 1e-9 else np.array([1.0, 0.0, 0.0])
    pitch = orbit_pitch(distraction, elevation_of(up))
    turn = _rotation(up, distraction.yaw) @ _rotation(across, pitch)
    roll = _rotation(np.array([0.0, 0.0, 1.0]), distraction.roll)
    return _translation(-focus) @ turn @ _translation(focus * distraction.zoom) @ roll


#: the difficulty from which the background hides the sky wholly (the suite's hardest level); below, in proportion
OPAQUE_FROM = 0.3


@dataclass(frozen=True)
class Background:
    """The pattern behind the scene: two colours a noise field blends (its `scale` across the view, `time` its
    fourth coordinate, which a dynamic episode plays), over the sky at `opacity`; drawn from ``background_seed``."""

    first: tuple[float, float, float]
    second: tuple[float, float, float]
    scale: float
    time: float
    opacity: float


def background(distraction: Distraction) -> Background | None:
    """The episode's background (None without one): a mean colour uniform in the colour cube, the two colours on
    either side of it by up to the difficulty (their contrast), a pattern of 2 to 8 blobs across the view, over the
    sky at an opacity of difficulty / :data:`OPAQUE_FROM` (at most 1)."""
    if distraction.background <= 0:
        return None
    rng = np.random.default_rng(distraction.background_seed)
    mean = rng.uniform(0.0, 1.0, size=3)
    spread = rng.uniform(-1.0, 1.0, size=3) * distraction.background
    first, second = np.clip(mean + spread, 0.0, 1.0), np.clip(mean - spread, 0.0, 1.0)
    scale, start = float(rng.uniform(2.0, 8.0)), float(rng.uniform(0.0, 100.0))
    return Background(
        tuple(first.tolist()),
        tuple(second.tolist()),
        scale,
        start + distraction.background_time,
        min(1.0, distraction.background / OPAQUE_FROM),
    )


def color_shifts(distraction: Distraction, count: int) -> np.ndarray:
    """(count + 1, 3) shifts of RGB in [-color_shift, color_shift]: one per material in the renderer's order, the
    sky's last. A dynamic episode's phase moves every shift along one direction of its own, inside the range."""
    rng = np.random.default_rng(distraction.colors_seed)
    base = rng.uniform(-1.0, 1.0, size=(count + 1, 3))
    direction = rng.uniform(-1.0, 1.0, size=(count + 1, 3))
    return np.clip(base + distraction.colors_phase * direction, -1.0, 1.0) * distraction.color_shift


class EpisodeDistractions:
    """An env's distractions across episodes: its generator (seeded by a seeded reset, else going on) and the current
    draw, which a dynamic setting moves every step. Pickles with the env's episode."""

    def __init__(self, settings: Distractions) -> None:
        """Lists the settings' videos now, so that a missing folder or video is an error before the first episode."""
        videos_of(settings)
        self.settings = settings
        self.rng: np.random.Generator | None = None
        self.current: Distraction | None = None

    def begin(self, np_random: np.random.Generator, seeded: bool) -> None:
        """A new episode's draw; a seeded reset (or the first) starts the generator from the env's seed."""
        if seeded or self.rng is None:
            seed_seq = np_random.bit_generator.seed_seq
            assert isinstance(seed_seq, np.random.SeedSequence), "Gymnasium seeds np_random from a SeedSequence"
            self.rng = distraction_generator(seed_seq)
        self.current = draw(self.settings, self.rng)

    def advance(self) -> None:
        """One env step: a dynamic distraction drifts (:func:`drift`), a fixed one stays."""
        if self.settings.dynamic and self.rng is not None:
            self.current = drift(self.current, self.settings, self.rng)
