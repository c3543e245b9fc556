"""Gymnasium's MuJoCo envs, reproduced: the bundled ports step as InvertedPendulum-v5, HalfCheetah-v5 and Reacher-v5 do.

Same seed, same actions (float64, so neither side rounds them): qpos, qvel,
observation, reward, terminated and truncated agree to 1e-9 for 1,000 steps,
episodes reset as they end (the reset draws continue the seeded stream on both sides).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")
#: Gymnasium's own HalfCheetah-v5 loads its XML, whose settotalmass MuJoCo 3 deprecates (the port reads the pinned copy, which has none)
pytestmark = pytest.mark.filterwarnings("ignore:MuJoCo. compiler attribute:RuntimeWarning")
gym = pytest.importorskip("gymnasium")

from visualenv.env.visual_env import VisualEnv  # noqa: E402

SPECS = Path(__file__).resolve().parents[2] / "specs" / "mujoco"
PORTS = [
    ("inverted_pendulum.yaml", "InvertedPendulum-v5"),
    ("half_cheetah.yaml", "HalfCheetah-v5"),
    ("reacher.yaml", "Reacher-v5"),
]


def run_both(spec: str, gym_id: str, seed: int, steps: int) -> int:
    ours = VisualEnv(SPECS / spec, render=False)
    theirs = gym.make(gym_id)
    actions = np.random.default_rng(1000 + seed)
    obs_a, _ = ours.reset(seed=seed)
    obs_b, _ = theirs.reset(seed=seed)
    resets = 1
    assert obs_a.dtype == obs_b.dtype == np.float64 and ours.observation_space.shape == theirs.observation_space.shape
    np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=1e-9)
    low, high = theirs.action_space.low.astype(np.float64), theirs.action_space.high.astype(np.float64)
    for step in range(steps):
        action = actions.uniform(low, high)
        obs_a, rew_a, term_a, trunc_a, _ = ours.step(action)
        obs_b, rew_b, term_b, trunc_b, _ = theirs.step(action)
        where = f"{gym_id} seed {seed} step {step}"
        np.testing.assert_allclose(
            ours.unwrapped.data.qpos, theirs.unwrapped.data.qpos, rtol=0, atol=1e-9, err_msg=where
        )
        np.testing.assert_allclose(
            ours.unwrapped.data.qvel, theirs.unwrapped.data.qvel, rtol=0, atol=1e-9, err_msg=where
        )
        np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=1e-9, err_msg=where)
        assert abs(float(rew_a) - float(rew_b)) <= 1e-9, (where, rew_a, rew_b)
        assert (term_a, trunc_a) == (term_b, trunc_b), (where, term_a, trunc_a, term_b, trunc_b)
        if term_a or trunc_a:
            obs_a, _ = ours.reset()
            obs_b, _ = theirs.reset()
            resets += 1
            np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=1e-9, err_msg=where + " (reset)")
    return resets


@pytest.mark.parametrize("spec, gym_id", PORTS, ids=[p[1] for p in PORTS])
@pytest.mark.parametrize("seed", [0, 7, 123])
def test_port_equals_gymnasium(spec: str, gym_id: str, seed: int) -> None:
    resets = run_both(spec, gym_id, seed, 1000)
    if gym_id != "HalfCheetah-v5":  # its episodes are 1,000 steps: one reset; the others end (or truncate) often
        assert resets > 3, resets


def test_ports_expose_mujoco_model_and_data() -> None:
    import mujoco

    env = VisualEnv(SPECS / "half_cheetah.yaml", render=False)
    assert isinstance(env.unwrapped.model, mujoco.MjModel) and isinstance(env.unwrapped.data, mujoco.MjData)
    assert env.action_space.shape == (6,) and env.observation_space.shape == (17,)
    assert env.metadata["render_fps"] == 20  # 1 / (0.01 s * frame_skip 5), as Gymnasium's HalfCheetah-v5


@pytest.mark.parametrize("env_id", ["VisualInvertedPendulum-v0", "VisualHalfCheetah-v0", "VisualReacher-v0"])
def test_ports_are_registered(env_id: str) -> None:
    import visualenv  # noqa: F401  - registers the bundled specs

    env = gym.make(f"visualenv/{env_id}", render=False)
    obs, _ = env.reset(seed=1)
    assert obs.dtype == np.float64
    env.step(env.action_space.sample())
    env.close()
