"""Stable-Baselines3's protected methods (visualenv/compat/sb3.py), checked on the installed SB3: a policy's constructor
arguments are the record SB3 saves with it, and a VecEnv's indices read as SB3's own VecEnvs read them."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

sb3 = pytest.importorskip("stable_baselines3")
torch = pytest.importorskip("torch")
from visualenv.compat import sb3 as compat  # noqa: E402


def test_sb3_is_a_version_this_module_was_checked_against():
    """Fails when Stable-Baselines3 moves: read BaseModel._get_constructor_parameters and VecEnv._get_indices in it,
    then add its version to CHECKED."""
    assert compat.checked(), f"stable-baselines3 {sb3.__version__} is not in compat/sb3.py's CHECKED {compat.CHECKED}"


def test_a_policys_constructor_parameters_are_what_sb3_saves_and_rebuild_it(tmp_path):
    from stable_baselines3.common.policies import ActorCriticPolicy

    observations, actions = gym.spaces.Box(-1, 1, (3,), np.float32), gym.spaces.Discrete(2)
    policy = ActorCriticPolicy(observations, actions, lambda _: 3e-4, net_arch=[8])
    parameters = compat.constructor_parameters(policy)
    assert parameters["observation_space"] == observations and parameters["net_arch"] == [8]
    policy.save(str(tmp_path / "policy.pt"))
    saved = torch.load(tmp_path / "policy.pt", weights_only=False)["data"]
    assert saved.keys() == parameters.keys()
    rebuilt = ActorCriticPolicy(**parameters)
    assert [p.shape for p in rebuilt.parameters()] == [p.shape for p in policy.parameters()]


def test_a_vec_envs_indices_read_as_sb3_reads_them():
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: gym.make("CartPole-v1")] * 3)
    try:
        read = [list(compat.vec_env_indices(venv, indices)) for indices in (None, 1, [0, 2])]
        assert read == [[0, 1, 2], [1], [0, 2]]
    finally:
        venv.close()


def test_an_algorithms_training_state_is_named_as_sb3_saves_it():
    """What `train --resume` saves as data: the torch objects SB3's save keeps, the counters it restores, the window of
    recent episodes."""
    from stable_baselines3 import PPO, SAC

    sac = SAC("MlpPolicy", gym.make("Pendulum-v1"), buffer_size=10, device="cpu")
    assert compat.state_names(sac) == (
        ["policy", "actor.optimizer", "critic.optimizer", "ent_coef_optimizer"],
        ["log_ent_coef"],
    )
    ppo = PPO("MlpPolicy", gym.make("CartPole-v1"), n_steps=16, batch_size=16, device="cpu", stats_window_size=7)
    assert compat.state_names(ppo) == (["policy", "policy.optimizer"], [])
    counters = compat.training_counters(ppo)
    assert counters == {"num_timesteps": 0, "_n_updates": 0, "_episode_num": 0, "_current_progress_remaining": 1.0}
    compat.set_training_counters(ppo, {**counters, "num_timesteps": 5, "_n_updates": 2})
    assert ppo.num_timesteps == 5 and compat.training_counters(ppo)["_n_updates"] == 2
    assert compat.episode_window(ppo) == 7


def test_an_update_loop_of_ones_own_reads_what_sacs_train_reads():
    """What DrQ's SAC's ``train`` takes from SB3: the learning rate its schedule gives now, a batch sampled as SB3
    samples it, its discounts, and the update count SB3 logs and a checkpoint restores."""
    from stable_baselines3 import SAC

    sac = SAC("MlpPolicy", gym.make("Pendulum-v1"), buffer_size=64, learning_starts=8, learning_rate=1e-3, device="cpu")
    sac.learn(8)
    sac.policy.set_training_mode(False)
    for group in sac.actor.optimizer.param_groups:
        group["lr"] = 0.5
    compat.start_updates(sac, [sac.actor.optimizer])
    assert sac.policy.training and [g["lr"] for g in sac.actor.optimizer.param_groups] == [1e-3]
    batch = compat.sample_batch(sac, 5)
    assert batch.observations.shape == (5, 3) and batch.rewards.shape == (5, 1)
    assert compat.batch_discounts(batch, 0.99) == 0.99  # a one-step buffer: gamma
    n_step = batch._replace(discounts=torch.full((5, 1), 0.5)) if "discounts" in batch._fields else batch
    assert compat.batch_discounts(n_step, 0.99) is n_step.discounts or "discounts" not in batch._fields
    assert compat.updates_made(sac) == 0
    compat.count_updates(sac, 3)
    assert compat.updates_made(sac) == 3 == compat.training_counters(sac)["_n_updates"]
