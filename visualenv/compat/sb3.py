"""Stable-Baselines3's protected methods visualenv calls: a policy's constructor arguments, a VecEnv's env indices.

**A policy's constructor arguments** (:func:`constructor_parameters`): policy.json records what rebuilds a policy as
data. SB3 keeps that record in ``BaseModel._get_constructor_parameters()``, which each policy class extends and which
``BaseModel.save`` stores next to the weights; SB3 has no public call that gives it without writing a file.

**A VecEnv's env indices** (:func:`vec_env_indices`): the ``indices`` argument of ``get_attr``, ``set_attr``,
``env_method`` and ``env_is_wrapped`` (None: every env; an int: that env; else the envs listed), read as SB3's own
VecEnvs read it, through ``VecEnv._get_indices``.

Neither has a documented alternative, so both are called on every version; ``tests/compat/test_sb3.py`` fails when
Stable-Baselines3 moves: another version (read these methods in it, then add it to :data:`CHECKED`), or a method gone.

Checked against Stable-Baselines3 2.3.0 to 2.8.0 (their source) and 2.9.2 (installed).
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
