"""Gymnasium's make (visualenv/compat/gymnasium.py): what make_time_limit relies on, checked on the installed Gymnasium.
tests/env/test_gymnasium_conventions.py checks the outcome through visualenv's own ids (truncated with outcome 'max_steps')."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

from visualenv.compat.gymnasium import CHECKED, checked, make_time_limit, restore_space_generator, space_generator

ID = "CompatProbe-v0"


class Probe(gym.Env):
    """An env that notes the limit make_time_limit reads while it is made."""

    observation_space = gym.spaces.Box(-1, 1, (1,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self) -> None:
        self.limit = None

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(1, np.float32), {}

    def step(self, action):
        return np.zeros(1, np.float32), 0.0, False, False, {}


def make_probe() -> Probe:
    probe = Probe()
    probe.limit = make_time_limit()  # called from the entry point itself, as visualenv.make calls it
    return probe


@pytest.fixture
def registered():
    gym.register(ID, entry_point=make_probe, max_episode_steps=7)
    yield
    gym.registry.pop(ID, None)


def test_gymnasium_is_a_version_make_time_limit_was_checked_against():
    """Fails when Gymnasium moves: read the new gymnasium.make (its frame's max_episode_steps and env_spec; whether the
    spec it sets on the env now holds the limit, the documented route), then add its version to CHECKED."""
    assert checked(), f"gymnasium {gym.__version__} is not in compat/gymnasium.py's CHECKED {CHECKED}"


def test_the_limit_is_kept_outside_the_env_and_read_from_make(registered):
    """Why the frame is read: the spec gymnasium.make sets on the env has no limit, the TimeLimit wrapper outside
    has it. When this fails because the env's own spec holds the limit, read that instead."""
    for asked, limit in ((None, 7), (3, 3), (12, 12)):
        env = gym.make(ID, **({} if asked is None else {"max_episode_steps": asked}))
        assert env.unwrapped.spec.max_episode_steps is None, (
            "gymnasium.make now sets the limit on the env's spec: use it"
        )
        assert env.spec.max_episode_steps == limit and env.unwrapped.limit == limit
    assert gym.make(ID, max_episode_steps=-1).unwrapped.limit is None  # no TimeLimit at all
    assert make_probe().limit is None  # another caller than gymnasium.make


def test_a_space_generator_is_read_without_making_one_and_put_back():
    """Why the attribute is read and written: ``np_random`` makes a generator on first use and has no setter. When this
    fails because Gymnasium gives it a setter (or a documented reader), use that instead."""
    space = gym.spaces.Discrete(5)
    assert space_generator(space) is None and space_generator(space) is None  # reading made none
    assert type(space).np_random.fset is None, "Space.np_random has a setter now: restore the generator through it"
    space.seed(3)
    generator = space_generator(space)
    assert generator is space.np_random
    expected = [space.sample() for _ in range(5)]
    other = gym.spaces.Discrete(5)
    restore_space_generator(other, pickle.loads(pickle.dumps(generator)))
    restore_space_generator(space, pickle.loads(pickle.dumps(generator)))
    assert [other.sample() for _ in range(5)] == [space.sample() for _ in range(5)] != expected
