"""Visual CartPole's dynamics are exactly Gymnasium's CartPole (state-only mode)."""

import gymnasium as gym
import numpy as np
import pytest

import visualenv

SPEC = "specs/visual_cartpole.yaml"


def run_pair(seed: int, policy) -> int:
    ours = visualenv.make(SPEC, render=False)
    theirs = gym.make("CartPole-v1").unwrapped
    ours.reset(seed=seed)
    theirs.reset(seed=seed)
    # same initial state: ours drew it from the same seed; set theirs explicitly anyway
    start = np.array(list(ours.unwrapped.state.values()))
    np.testing.assert_allclose(start, theirs.state, rtol=0, atol=1e-12)
    theirs.state = start.copy()
    for t in range(1000):
        action = policy(t, theirs.state)
        _, reward, terminated, truncated, info = ours.step(action)
        _, their_reward, their_terminated, _, _ = theirs.step(action)
        np.testing.assert_allclose(np.array(list(info["state"].values())), theirs.state, rtol=0, atol=1e-9)
        assert reward == their_reward == 1.0
        if their_terminated:
            assert terminated and info["outcome"] == "fell", (t, info)
            return t + 1
        if truncated:  # our spec truncates at 200 steps; Gymnasium's CartPole-v1 at 500
            assert t + 1 == 200 and info["outcome"] == "max_steps"
            return t + 1
        assert not terminated
    raise AssertionError("episode did not end")


@pytest.mark.parametrize("seed", range(12))
def test_random_actions_match_gymnasium(seed):
    rng = np.random.default_rng(seed)
    length = run_pair(seed, lambda t, s: int(rng.integers(2)))
    assert 8 <= length <= 200


def test_balancing_policy_matches_until_truncation():
    # push toward the side the pole leans: keeps it up for the whole episode
    length = run_pair(3, lambda t, s: int(s[2] + 0.5 * s[3] > 0))
    assert length == 200


@pytest.mark.parametrize("action", [0, 1])
def test_constant_push_terminates_like_gymnasium(action):
    assert run_pair(7, lambda t, s: action) < 40


def test_success_is_balanced_for_more_than_100_steps():
    env = visualenv.make(SPEC, render=False)
    env.reset(seed=3)
    info = {}
    for t in range(200):
        s = env.unwrapped.state
        _, _, terminated, truncated, info = env.step(int(s["theta"] + 0.5 * s["theta_dot"] > 0))
        assert info["is_success"] is (t + 1 > 100), t  # steps done = t + 1
        if terminated or truncated:
            break
    assert info["is_success"] is True and info["milestones"] == ["balanced"]
