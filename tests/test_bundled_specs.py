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
    assert magnitudes.min() >= 5 and magnitudes.max() <= 25 and (np.array(angles) < 0).any() and (np.array(angles) > 0).any()
    env.reset(seed=0)
    assert [env.step(a)[4]["state"]["gx"] for a in (1, 1, 0)] == [1.0, 2.0, 1.0]
