"""Envs rendering in turn in one process (each render rebuilds Cycles' session) are told once what to do instead."""

from __future__ import annotations

import warnings

import pytest

import visualenv

pytestmark = pytest.mark.blender


@pytest.fixture
def fresh_count(monkeypatch):
    from visualenv.render.blender.runtime import scene_turns

    for name, value in (("_last", None), ("_renders", 0), ("_turns", 0), ("_told", False)):
        monkeypatch.setattr(scene_turns, name, value)
    return scene_turns


def _steps(envs, rounds: int, each: int = 1) -> list[warnings.WarningMessage]:
    for env in envs:
        env.reset(seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(rounds):
            for env in envs:
                for _ in range(each):
                    if any(env.step(0)[2:4]):  # terminated or truncated
                        env.reset()
    return [w for w in caught if "render in turn" in str(w.message)]


def test_two_envs_stepped_in_turn_are_told_once(fresh_count):
    envs = [visualenv.make("VisualCartPole-v0") for _ in range(2)]
    try:
        told = _steps(envs, fresh_count.WINDOW * 2)  # two windows: the second is not told again
    finally:
        for env in envs:
            env.close()
    assert len(told) == 1 and "batched=True" in str(told[0].message)
    assert told[0].filename == __file__  # the line of the caller's step(), not one inside visualenv or gymnasium


def test_an_eval_env_rendered_now_and_then_beside_a_training_env_is_not_told(fresh_count):
    train, evaluate = visualenv.make("VisualCartPole-v0"), visualenv.make("VisualCartPole-v0")
    try:
        told = _steps([train, evaluate], 8, each=fresh_count.WINDOW // 4)
    finally:
        train.close()
        evaluate.close()
    assert told == []
