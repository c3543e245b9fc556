"""What one env and a batch make of their keywords (visualenv.env.construction), and the spaces of a model without
actuators."""

from __future__ import annotations

from pathlib import Path

import pytest

from visualenv.env.batch import BatchedVectorEnv
from visualenv.env.visual_env import VisualEnv

MODEL = """<mujoco><worldbody><body pos="0 0 1"><joint type="slide" axis="0 0 1"/><geom size=".1"/></body>
</worldbody></mujoco>"""


@pytest.mark.parametrize("repeat", [0, -1, 1.5, True])
def test_an_action_repeat_below_one_is_refused_by_one_env_and_a_batch(repeat) -> None:
    for make in (
        lambda: VisualEnv("VisualCartPole-v0", render=False, action_repeat=repeat),
        lambda: BatchedVectorEnv("VisualCartPole-v0", 2, render=False, action_repeat=repeat),
    ):
        with pytest.raises(ValueError, match="action_repeat must be an integer of at least 1"):
            make()


def test_one_env_and_a_batch_take_an_id_and_agree_on_the_episode_length() -> None:
    one = VisualEnv("DMC-cartpole-swingup-v0", render=False, max_episode_steps=50, action_repeat=4)
    batch = BatchedVectorEnv("DMC-cartpole-swingup-v0", 2, render=False, max_episode_steps=50, action_repeat=4)
    assert (one.action_repeat, one.max_episode_steps) == (batch.action_repeat, batch.max_episode_steps) == (4, 50)
    batch.close()


def test_a_model_without_actuators_has_an_empty_action_space_and_falls(tmp_path: Path) -> None:
    pytest.importorskip("mujoco")
    (tmp_path / "m.xml").write_text(MODEL)
    (tmp_path / "s.yaml").write_text("id: Falling-v0\nphysics: {model: m.xml}\nreward: 0\nmax_steps: 10\n")
    env = VisualEnv(tmp_path / "s.yaml", render=False)
    assert env.action_space.shape == (0,)
    env.reset(seed=0)
    obs, *_ = env.step(env.action_space.sample())
    assert obs[1] < 0, "nothing holds the body: it falls"
