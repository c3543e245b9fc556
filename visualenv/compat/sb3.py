"""Stable-Baselines3's protected methods and attributes visualenv uses: a policy's constructor arguments, a VecEnv's env
indices, an algorithm's training state.

**A policy's constructor arguments** (:func:`constructor_parameters`): policy.json records what rebuilds a policy as
data. SB3 keeps that record in ``BaseModel._get_constructor_parameters()``, which each policy class extends and which
``BaseModel.save`` stores next to the weights; SB3 has no public call that gives it without writing a file.

**A VecEnv's env indices** (:func:`vec_env_indices`): the ``indices`` argument of ``get_attr``, ``set_attr``,
``env_method`` and ``env_is_wrapped`` (None: every env; an int: that env; else the envs listed), read as SB3's own
VecEnvs read it, through ``VecEnv._get_indices``.

**An update loop of one's own** (:func:`start_updates`, :func:`sample_batch`, :func:`batch_discounts`): what a
subclass that replaces SAC's ``train`` (``visualenv.train.drq.DrQSAC``) does as SB3's ``train`` does: the learning
rates of ``_update_learning_rate``, the replay buffer sampled with ``_vec_normalize_env``, and the n-step batches'
``discounts`` (SB3 2.7 and later; before, gamma).

**An algorithm's training state** (:func:`state_names`, :func:`training_counters`, :func:`set_training_counters`,
:func:`episode_window`): what ``train --resume`` saves as data where SB3's ``save`` pickles it. The torch objects are
those ``BaseAlgorithm._get_torch_save_params()`` names (state dicts of the policy and the optimizers, and tensors
such as SAC's ``log_ent_coef``); the counters are the attributes SB3's ``save`` keeps that a new model starts at 0
(``num_timesteps``, ``_n_updates``, ``_episode_num``, DQN's ``_n_calls`` and ``exploration_rate``,
``_current_progress_remaining``); ``_stats_window_size`` bounds the recent episodes' buffer.

None has a documented alternative, so each is used on every version; ``tests/compat/test_sb3.py`` fails when
Stable-Baselines3 moves: another version (read these methods in it, then add it to :data:`CHECKED`), or a method gone.

Checked against Stable-Baselines3 2.3.0 to 2.8.0 (their source) and 2.9.2 (installed); the training state against
2.9.2 alone.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

#: the Stable-Baselines3 versions (major.minor) whose protected methods were read for what this module relies on
CHECKED = ("2.3", "2.4", "2.5", "2.6", "2.7", "2.8", "2.9")


def checked() -> bool:
    """Whether the installed Stable-Baselines3 is one this module was checked against (this imports it)."""
    import stable_baselines3

    return ".".join(stable_baselines3.__version__.split(".")[:2]) in CHECKED


def constructor_parameters(policy: Any) -> dict[str, Any]:
    """The keyword arguments that rebuild `policy` (an SB3 policy), as SB3 records them when it saves the policy."""
    return dict(policy._get_constructor_parameters())


def vec_env_indices(venv: Any, indices: Any) -> Iterable[int]:
    """The envs of `venv` (an SB3 VecEnv) that `indices` names: None every env, an int that env, else those listed."""
    return venv._get_indices(indices)


#: the counters SB3's ``save`` keeps that a new model starts from 0 (or 1.0): those an algorithm has are carried
COUNTERS = (
    "num_timesteps",
    "_n_updates",
    "_episode_num",
    "_n_calls",
    "_current_progress_remaining",
    "exploration_rate",
)


def state_names(model: Any) -> tuple[list[str], list[str]]:
    """The torch state of an SB3 algorithm, as its ``save`` names it: the attributes whose state dicts it keeps
    (``policy``, ``policy.optimizer``, SAC's ``actor.optimizer``, ...), and those that are tensors (``log_ent_coef``)."""
    state_dicts, variables = model._get_torch_save_params()
    return list(state_dicts), list(variables)


def training_counters(model: Any) -> dict[str, int | float]:
    """The counters of :data:`COUNTERS` that `model` has, as numbers."""
    return {name: getattr(model, name) for name in COUNTERS if hasattr(model, name)}


def set_training_counters(model: Any, counters: dict[str, int | float]) -> None:
    """Set the counters :func:`training_counters` read (each one `model` has; the caller checked the names)."""
    for name, value in counters.items():
        setattr(model, name, value)


def episode_window(model: Any) -> int:
    """How many recent episodes SB3 keeps for its ``rollout/ep_rew_mean`` (``stats_window_size``)."""
    return int(model._stats_window_size)


def start_updates(model: Any, optimizers: list[Any]) -> None:
    """What SB3's off-policy ``train`` does before its updates: the policy in training mode, `optimizers` at the
    learning rate its schedule gives now."""
    model.policy.set_training_mode(True)
    model._update_learning_rate(optimizers)


def sample_batch(model: Any, batch_size: int) -> Any:
    """A batch of `model`'s replay buffer, its rewards normalised as SB3's ``train`` normalises them (VecNormalize)."""
    return model.replay_buffer.sample(batch_size, env=model._vec_normalize_env)


def batch_discounts(samples: Any, gamma: float) -> Any:
    """The discount of each transition of `samples`: an n-step buffer's own (SB3 2.7 and later), else `gamma`."""
    discounts = getattr(samples, "discounts", None)
    return gamma if discounts is None else discounts


def updates_made(model: Any) -> int:
    """How many gradient updates `model` has made (SB3's ``train/n_updates``; a resumed run's checkpoint restores it)."""
    return int(model._n_updates)


def count_updates(model: Any, updates: int) -> None:
    """Add `updates` to the count :func:`updates_made` reads, as SB3's ``train`` does after its updates."""
    model._n_updates += updates
