"""The distractions' camera and floor as the Distracting Control Suite defines them (docs/distractions.md), checked on
the numbers alone, without rendering: the camera's pose each draw gives (:func:`orbit`, what the renderers apply) from
the DMC ids' own cameras, read from their MuJoCo models.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

from visualenv.compiler.render_plan import to_plan
from visualenv.render.distractions import (
    Distraction,
    axis_focus,
    draw,
    drift,
    elevation_of,
    is_limited,
    orbit,
    orbit_pitch,
    world_up,
    zoom_range,
)
from visualenv.spec.options import DISTRACTION_LEVELS, distraction_settings, floor_alpha

ROOT = Path(__file__).resolve().parents[2]
#: one DMC spec per model and camera (cartpole's four tasks share one)
SPECS = list(
    {
        (
            spec.read_text(encoding="utf-8").split("model:")[1].split()[0],
            yaml.safe_load(spec.read_text())["observation"]["camera"],
        ): spec
        for spec in sorted((ROOT / "specs" / "dmc").glob("*.yaml"))
    }.values()
)
DRAWS = 4000


def camera_pose(spec: Path) -> np.ndarray:
    """The spec's observation camera's pose at qpos0 (4x4 in the world; MuJoCo's camera frame is Blender's)."""
    data = yaml.safe_load(spec.read_text(encoding="utf-8"))
    model = mujoco.MjModel.from_xml_path(str(spec.parent / data["physics"]["model"]))
    state = mujoco.MjData(model)
    mujoco.mj_forward(model, state)
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, data["observation"]["camera"])
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = state.cam_xmat[i].reshape(3, 3), state.cam_xpos[i]
    return pose


def settings(level: float | str, model: str, **given):
    chosen = distraction_settings(
        {"difficulty": DISTRACTION_LEVELS.get(level, level) if isinstance(level, str) else level, **given}, None, model
    )
    return to_plan(chosen)


def orbited(pose: np.ndarray, distraction: Distraction) -> tuple[np.ndarray, np.ndarray]:
    """The orbited camera's place and the point it orbits, in the world (the renderer's ray cast stands in by 3 m)."""
    focus = axis_focus(pose)
    focus = focus if focus > 0.01 else 3.0
    centre = pose @ np.array([0.0, 0.0, -focus, 1.0])
    return (pose @ orbit(distraction, focus, world_up(pose)))[:3, 3], centre[:3]


@pytest.mark.parametrize("spec", SPECS, ids=lambda p: p.stem)
def test_no_draw_puts_a_camera_below_the_plane_through_its_centre(spec: Path) -> None:
    """Every DMC model's camera but reacher's: at or above the horizontal plane through the point it orbits, and not
    past overhead, at the hardest level, fixed and drifting; reacher's (looking straight down) is not limited."""
    data = yaml.safe_load(spec.read_text(encoding="utf-8"))
    chosen = settings("hard", data["physics"]["model"])
    pose = camera_pose(spec)
    limited = is_limited(Distraction(upper_hemisphere=chosen.upper_hemisphere), elevation_of(world_up(pose)))
    assert limited == ("reacher" not in spec.stem)
    rng = np.random.default_rng(0)
    heights = []
    for _ in range(DRAWS // 32):
        current = draw(chosen, rng)
        for _ in range(8):  # a draw, then a dynamic episode's drift from it
            place, centre = orbited(pose, current)
            heights.append((place[2] - centre[2]) / np.linalg.norm(place - centre))
            current = drift(current, chosen, rng)
    elevation = np.degrees(np.arcsin(np.clip(heights, -1, 1)))
    if limited:
        assert elevation.min() >= -1e-6 and elevation.max() <= 90 + 1e-6, (elevation.min(), elevation.max())


def test_the_cartpole_camera_is_drawn_uniformly_inside_the_narrowed_interval() -> None:
    """DMC cartpole's camera is level with its centre (elevation 0): it rises by up to d x pi/2, uniformly, with no
    draws piled on a bound; unlimited, half the draws would be below it (21.6 % under the floor at hard)."""
    pose = camera_pose(ROOT / "specs" / "dmc" / "cartpole_swingup.yaml")
    assert abs(elevation_of(world_up(pose))) < 1e-9
    rng = np.random.default_rng(1)
    for level, d in DISTRACTION_LEVELS.items():
        chosen = settings(level, "cartpole.xml")
        reach = d * math.pi / 2
        draws = [draw(chosen, rng) for _ in range(DRAWS)]
        places = np.array([orbited(pose, x) for x in draws])  # (draws, camera and centre, xyz)
        offsets = places[:, 0] - places[:, 1]
        angles = np.arcsin(np.clip(offsets[:, 2] / np.linalg.norm(offsets, axis=1), -1, 1))
        assert angles.min() >= -1e-9 and angles.max() <= reach + 1e-9
        assert angles.min() < 0.01 * reach and angles.max() > 0.99 * reach  # the whole interval is reached
        counts, _ = np.histogram(angles, bins=10, range=(0, reach))
        assert counts.min() > 0.8 * DRAWS / 10 and counts.max() < 1.2 * DRAWS / 10, counts  # uniform: none piled
        assert np.allclose([orbit_pitch(x, 0.0) for x in draws], -angles, atol=1e-9)
    assert axis_focus(pose) == pytest.approx(4.0)


def test_zoom_is_the_suites_range_and_drift_keeps_it() -> None:
    """The distance to the centre times a factor uniform in [1 - d/2, 1 + 1.5 d], drawn and drifting."""
    pose = camera_pose(ROOT / "specs" / "dmc" / "cartpole_swingup.yaml")
    rng = np.random.default_rng(2)
    for level, d in DISTRACTION_LEVELS.items():
        low, high = zoom_range(d)
        assert (low, high) == pytest.approx((1 - 0.5 * d, 1 + 1.5 * d))
        chosen = settings(level, "cartpole.xml")
        draws = [draw(chosen, rng) for _ in range(DRAWS)]
        zooms = np.array([x.zoom for x in draws])
        assert zooms.min() >= low and zooms.max() <= high
        assert zooms.min() < low + 0.01 * (high - low) and zooms.max() > high - 0.01 * (high - low)
        assert abs(zooms.mean() - (low + high) / 2) < 0.02 * (high - low)
        place, centre = orbited(pose, draws[0])
        assert np.linalg.norm(place - centre) == pytest.approx(4.0 * draws[0].zoom)
        current = draws[0]
        for _ in range(500):
            current = drift(current, chosen, rng)
            assert low <= current.zoom <= high and abs(current.pitch) <= d * math.pi / 2 + 1e-12


def test_a_spec_says_whether_the_limit_applies() -> None:
    """upper_hemisphere: false frees the level camera below its centre; true limits even a camera looking down."""
    rng = np.random.default_rng(3)
    free = settings("hard", "cartpole.xml", upper_hemisphere=False)
    pitches = np.array([orbit_pitch(draw(free, rng), 0.0) for _ in range(DRAWS)])
    assert pitches.max() > 0.99 * 0.3 * math.pi / 2 and pitches.min() < -0.99 * 0.3 * math.pi / 2
    down = math.pi / 2  # reacher's camera: not limited by default, limited when the spec says so
    assert not is_limited(Distraction(), down) and is_limited(Distraction(upper_hemisphere=True), down)
    forced = settings("hard", "reacher.xml", upper_hemisphere=True)
    pitches = np.array([orbit_pitch(draw(forced, rng), down) for _ in range(DRAWS)])
    assert pitches.min() >= 0.0  # a positive pitch lowers it from overhead


@pytest.mark.parametrize(
    ("model", "alpha"),
    [("assets/reacher.xml", 0.0), ("walker.xml", 1.0), ("cheetah.xml", 1.0), ("assets/cartpole.xml", 0.3), (None, 0.3)],
)
def test_the_floor_alpha_is_the_suites_by_domain_when_asked(model: str | None, alpha: float) -> None:
    """'dcs' takes the suite's alpha for the domain; by default the floor stays opaque (a partial alpha at 1 sample is
    per-pixel noise, not the suite's blend)."""
    assert floor_alpha(model) == alpha
    assert settings(0.2, model, floor_alpha="dcs").floor_alpha == alpha
    assert draw(settings(0.2, model, floor_alpha="dcs"), np.random.default_rng(0)).floor_alpha == alpha
    assert settings(0.2, model, floor_alpha=0.5).floor_alpha == 0.5
    assert settings(0.2, model).floor_alpha is None
    assert draw(settings(0.2, model), np.random.default_rng(0)).floor_alpha == 1.0


def test_a_range_of_difficulties_draws_each_episodes_uniformly_in_it() -> None:
    """difficulty: [low, high] draws an episode's difficulty uniformly between them, and everything else at it (the
    colours' and background's scale, the camera's reach, its zoom and its drift); a single difficulty draws as before."""
    rng = np.random.default_rng(4)
    ranged = settings([0.05, 0.35], "cartpole.xml")
    assert ranged.largest == 0.35
    draws = [draw(ranged, rng) for _ in range(DRAWS)]
    levels = np.array([x.difficulty for x in draws])
    assert levels.min() >= 0.05 and levels.max() <= 0.35 and abs(levels.mean() - 0.2) < 0.01
    assert np.histogram(levels, bins=6, range=(0.05, 0.35))[0].min() > DRAWS / 6 * 0.8
    for x in draws[:200]:
        assert x.color_shift == x.background == x.difficulty
        assert x.reach == pytest.approx(x.difficulty * math.pi / 2)
        low, high = zoom_range(x.difficulty)
        assert low <= x.zoom <= high
        current = x
        for _ in range(20):
            current = drift(current, ranged, rng)
            assert low <= current.zoom <= high and abs(current.yaw) <= x.reach + 1e-12
    fixed = draw(settings(0.3, "cartpole.xml"), np.random.default_rng(5))
    assert fixed.difficulty == 0.3 and fixed == draw(settings(0.3, "cartpole.xml"), np.random.default_rng(5))


@pytest.mark.parametrize(
    ("given", "message"),
    [([0.3, 0.1], "low <= high"), ([0.1, 1.5], "less than or equal to 1"), ([0.1], "at least 2 items")],
)
def test_a_bad_range_is_refused_with_what_was_expected(given: list[float], message: str) -> None:
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match=message):
        distraction_settings({"difficulty": given}, None)
