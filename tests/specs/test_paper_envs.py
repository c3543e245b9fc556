"""The paper's environments: episodes end for the documented reasons with the stated rewards."""

import math

import numpy as np
import pytest

import visualenv


def run(env_id, policy, seed, **kwargs):
    env = visualenv.make(env_id, render=False, **kwargs)
    _, info = env.reset(seed=seed)
    total = 0.0
    while True:
        _, reward, terminated, truncated, info = env.step(policy(info["state"]))
        total += reward
        if terminated or truncated:
            return info, total, terminated, truncated


# -- Hover2D -----------------------------------------------------------------------------------------


def fly_to_target(s):
    dx, dy = s["tx"] - s["x"] - 3 * s["vx"], s["ty"] - s["y"] - 3 * s["vy"]  # aim ahead of the drift
    if abs(dx) > abs(dy):
        return 3 if dx > 0 else 2
    return 0 if dy > 0 else 1


@pytest.mark.parametrize("seed", range(5))
def test_hover2d_reaching_the_target_is_a_success_worth_20(seed):
    info, total, terminated, _ = run("Hover2D-v0", fly_to_target, seed)
    assert terminated and info["outcome"] == "reached" and info["is_success"] and total == 20.0
    s = info["state"]
    assert math.hypot(s["x"] - s["tx"], s["y"] - s["ty"]) < 2.0


def test_hover2d_leaving_the_bounds_costs_20():
    env = visualenv.make("Hover2D-v0", render=False)
    env.reset(seed=0, options={"state": {"x": 0, "y": 0, "tx": -5, "ty": 5}})
    total = 0.0
    while True:
        _, r, terminated, truncated, info = env.step(3)  # keep pushing right
        total += r
        if terminated or truncated:
            break
    assert terminated and info["outcome"] == "out_of_bounds" and total == -20.0 and not info["is_success"]
    assert abs(info["state"]["x"]) > 10


def test_hover2d_surviving_the_step_limit_pays_10():
    # alternate left/right: stays near the start, far from a target placed away from it
    env = visualenv.make("Hover2D-v0", render=False)
    env.reset(seed=0, options={"state": {"x": -5, "y": -5, "tx": 5, "ty": 5}})
    total, t = 0.0, 0
    while True:
        _, r, terminated, truncated, info = env.step(2 + t % 2)
        total, t = total + r, t + 1
        if terminated or truncated:
            break
    assert truncated and not terminated and info["outcome"] == "survived" and total == 10.0 and t == 100


def test_hover2d_targets_and_starts_are_random_within_bounds():
    env = visualenv.make("Hover2D-v0", render=False)
    states = [env.reset(seed=i)[1]["state"] for i in range(50)]
    for key in ("x", "y", "tx", "ty"):
        values = np.array([s[key] for s in states])
        assert values.min() >= -6 and values.max() <= 6 and values.std() > 2


def test_hover2d_pulse_settles_at_one_metre_per_step():
    env = visualenv.make("Hover2D-v0", render=False)
    env.reset(seed=0, options={"state": {"x": -9.5, "y": 0, "tx": 9, "ty": 9}})
    xs = [env.step(3)[4]["state"]["x"] for _ in range(15)]
    assert np.diff(xs)[-1] == pytest.approx(1.0, abs=0.05)


# -- Goalie ------------------------------------------------------------------------------------------


def goalie_expert(s):
    # move toward where the ball will cross the line
    steps_left = s["ball_y"] / math.cos(s["angle"])
    target = s["ball_x"] + steps_left * math.sin(s["angle"])
    return 1 if target > s["gx"] else 0


@pytest.mark.parametrize("seed", range(10))
def test_goalie_every_ball_can_be_caught(seed):
    info, total, terminated, _ = run("Goalie-v0", goalie_expert, seed)
    assert terminated and info["outcome"] == "caught" and total == 10.0 and info["is_success"]
    assert abs(info["state"]["gx"] - info["state"]["ball_x"]) <= 1


def test_goalie_missing_the_ball_costs_10():
    info, total, terminated, _ = run("Goalie-v0", lambda s: 0 if s["angle"] > 0 else 1, seed=1)  # run away from it
    assert terminated and info["outcome"] in ("scored", "left_goal") and total == -10.0 and not info["is_success"]


def test_goalie_leaving_the_goal_costs_10():
    env = visualenv.make("Goalie-v0", render=False, params={"length": 40.0})
    env.reset(seed=0)
    for _ in range(13):
        _, r, terminated, _, info = env.step(1)
    assert terminated and info["outcome"] == "left_goal" and r == -10.0


def test_goalie_moves_exactly_one_unit_and_ball_angle_is_within_limits():
    env = visualenv.make("Goalie-v0", render=False)
    angles = []
    for seed in range(100):
        _, info = env.reset(seed=seed)
        angles.append(info["state"]["angle"])
    magnitudes = np.degrees(np.abs(angles))
    assert (
        magnitudes.min() >= 5
        and magnitudes.max() <= 25
        and (np.array(angles) < 0).any()
        and (np.array(angles) > 0).any()
    )
    env.reset(seed=0)
    assert [env.step(a)[4]["state"]["gx"] for a in (1, 1, 0)] == [1.0, 2.0, 1.0]


# -- LunarLanding ------------------------------------------------------------------------------------


def lander_autopilot(s):
    """A state-feedback pilot: steer over the zone, sink at a speed that shrinks with altitude, hold it with thrust."""
    side = float(np.clip(1.5 * (0.4 * (s["tx"] - s["x"]) - 1.2 * s["vx"]), -1, 1))
    want_vz = -max(0.6, min(3.0, 0.3 * s["z"]))
    mass = 1.0 + 0.5 * s["fuel"]
    throttle = float(np.clip((1.62 + 2.0 * (want_vz - s["vz"])) * mass / 5.4, 0, 1))
    return np.array([2 * throttle - 1, side], np.float32)


@pytest.mark.parametrize("seed", range(5))
def test_lunar_landing_a_soft_landing_in_the_zone_is_a_success_worth_10(seed):
    info, total, terminated, _ = run("LunarLanding-v0", lander_autopilot, seed)
    s = info["state"]
    assert terminated and info["outcome"] == "landed" and info["is_success"]
    assert s["z"] <= 0 and abs(s["x"] - s["tx"]) <= 3 and abs(s["vz"]) <= 2 and 0 < s["fuel"] < 1
    assert total > 10  # the landing bonus plus the shaping earned on the way down


def test_lunar_landing_with_the_engine_off_crashes_and_at_half_throttle_climbs_away():
    info, total, terminated, _ = run("LunarLanding-v0", lambda s: np.array([-1.0, 0.0], np.float32), seed=0)
    assert terminated and info["outcome"] == "crashed" and not info["is_success"]
    assert info["state"]["vz"] < -2
    info, total, terminated, _ = run("LunarLanding-v0", lambda s: np.zeros(2, np.float32), seed=0)
    assert terminated and info["outcome"] == "out_of_bounds" and info["state"]["z"] > 40


def test_lunar_landing_a_soft_touchdown_outside_the_zone_is_a_miss():
    info, total, terminated, _ = run("LunarLanding-v0", lambda s: lander_autopilot({**s, "tx": s["tx"] + 12}), seed=0)
    assert terminated and info["outcome"] == "missed" and not info["is_success"]


def test_lunar_landing_hovering_burns_the_fuel_and_drifting_leaves_the_area():
    def hover(s):  # brake to a stop and stay there
        throttle = np.clip((1.62 - 2.0 * s["vz"]) * (1.0 + 0.5 * s["fuel"]) / 5.4, 0, 1)
        return np.array([2 * throttle - 1, np.clip(-2.0 * s["vx"], -1, 1)], np.float32)

    info, total, terminated, _ = run("LunarLanding-v0", hover, seed=0)
    assert terminated and info["outcome"] == "out_of_fuel" and info["state"]["fuel"] == 0 and info["state"]["z"] > 20
    info, _, terminated, _ = run("LunarLanding-v0", lambda s: np.array([hover(s)[0], 1.0], np.float32), seed=0)
    assert terminated and info["outcome"] == "out_of_bounds" and info["state"]["x"] > 25


def test_lunar_landing_thrust_is_divided_by_a_mass_that_falls_as_fuel_burns():
    env = visualenv.make("LunarLanding-v0", render=False)
    env.reset(seed=0, options={"state": {"x": 0.0, "z": 20.0, "vx": 0.0, "vz": 0.0, "fuel": 1.0, "tx": 0.0}})
    _, _, _, _, info = env.step(np.array([1.0, 1.0], np.float32))  # full main and side thrust for 0.5 s
    full = info["state"]
    assert full["vz"] == pytest.approx(0.5 * (5.4 / 1.5 - 1.62))
    assert full["vx"] == pytest.approx(0.5 * 1.0 / 1.5)
    assert full["fuel"] == pytest.approx(1 - 0.025 - 0.01)
    env.reset(seed=0, options={"state": {"x": 0.0, "z": 20.0, "vx": 0.0, "vz": 0.0, "fuel": 0.2, "tx": 0.0}})
    _, _, _, _, info = env.step(np.array([1.0, 0.0], np.float32))
    assert info["state"]["vz"] == pytest.approx(0.5 * (5.4 / 1.1 - 1.62))  # lighter: the same thrust pushes harder


def test_lunar_landing_starts_and_zones_are_random_within_their_ranges():
    env = visualenv.make("LunarLanding-v0", render=False)
    starts = np.array([env.reset(seed=seed)[0] for seed in range(200)])  # x, z, vx, vz, fuel, tx
    for column, (low, high) in enumerate([(-8, 8), (24, 30), (-1, 1), (-2, -1), (1, 1), (-8, 8)]):
        assert starts[:, column].min() >= low and starts[:, column].max() <= high
    assert starts[:, 5].std() > 3 and starts[:, 0].std() > 3


@pytest.mark.blender
def test_lunar_landing_the_camera_rides_the_lander_so_the_zone_grows_and_shifts():
    pytest.importorskip("bpy")
    env = visualenv.make("LunarLanding-v0")

    def zone(x: float, z: float) -> tuple[int, float]:
        obs, _ = env.reset(seed=0, options={"state": {"x": x, "z": z, "vx": 0.0, "vz": 0.0, "fuel": 1.0, "tx": 0.0}})
        bright = obs[..., 0] > 225  # the glowing zone is the brightest thing on the ground
        return int(bright.sum()), float(np.nonzero(bright)[1].mean())

    high_area, high_col = zone(0.0, 25.0)
    low_area, low_col = zone(0.0, 8.0)
    assert low_area > 4 * high_area > 0  # seen from a third of the height: about 9 times the area
    assert abs(high_col - 49.5) < 3 and abs(low_col - 49.5) < 3
    _, left_col = zone(6.0, 25.0)  # the lander east of the zone sees it to the west
    assert left_col < high_col - 5
    env.close()


def test_the_worked_example_in_the_docs_is_the_bundled_lunar_landing_spec():
    """docs/spec.md quotes LunarLanding's spec: every quoted line must still be in it, so the manual cannot drift."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    doc = (
        (root / "docs" / "spec.md")
        .read_text(encoding="utf-8")
        .split("## Worked example")[1]
        .split("```yaml")[1]
        .split("```")[0]
    )

    def code(line: str) -> str:  # without its comment, spaces collapsed
        return " ".join(line.split(" #")[0].split())

    spec = {code(line) for line in (root / "specs" / "lunar_landing.yaml").read_text(encoding="utf-8").splitlines()}
    quoted = [code(line) for line in doc.splitlines() if code(line)]
    assert len(quoted) > 20 and [line for line in quoted if line not in spec] == []
