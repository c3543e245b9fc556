"""Pickling a :class:`~visualenv.env.visual_env.VisualEnv`: the copy is rebuilt from the spec, then goes on with the
episode the original was in.

Kept apart from the env's step because it is a job of its own: what an episode is made of (state, step count, random
generators, MuJoCo's integration state), and how a copy that cannot carry it over says so and asks for ``reset()``.
"""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np

from visualenv.compat.gymnasium import restore_space_generator, space_generator
from visualenv.compiler.program import Program
from visualenv.expr.functions import RandomSource
from visualenv.physics.model_fields import restore_fields, written_fields
from visualenv.physics.simulation import integration_state
from visualenv.render.distractions import EpisodeDistractions


class PicklingEnv(gym.Env):
    """The pickling half of :class:`~visualenv.env.visual_env.VisualEnv`, which sets the attributes declared here."""

    program: Program
    _init_args: dict[str, Any]
    _random: RandomSource
    _legacy_random: np.random.RandomState | None
    _sim: Any
    _sensor_rng: np.random.Generator | None
    _distractions: EpisodeDistractions | None
    _last_obs: Any
    _state: tuple[float, ...]
    _steps: int
    _fired: int
    _done: bool
    _success: bool
    _was_reset: bool
    _not_carried: str | None

    def __getstate__(self) -> dict[str, Any]:
        """The spec and options, the Gymnasium spec, and the episode in progress.

        The episode is the state, step count, milestones and success, every random generator (the env's, the sensor
        noise's, the action space's) and a physics spec's MuJoCo state (``mjSTATE_INTEGRATION``: what ``mj_step``
        needs to go on bit for bit), with the model fields a reset writes (reacher's target). The renderer is not
        pickled: the copy builds its own on first render and poses the scene from the carried state. A
        ``dynamics.python`` hook is imported again by name: state it keeps in its own module is that module's in the
        receiving process.
        """
        episode = {
            "state": self._state,
            "steps": self._steps,
            "fired": self._fired,
            "done": self._done,
            "success": self._success,
            "np_random": self._np_random,
            "np_random_seed": self._np_random_seed,
            "sensor_rng": self._sensor_rng,
            "action_space_rng": space_generator(self.action_space),
            "last_obs": self._last_obs,
            "legacy_random": self._legacy_random,
            "physics": self._physics_state(),
            "model": written_fields(self._sim.model) if self._sim is not None else None,
            "distractions": self._distractions,
        }
        return {
            "loaded": self.program.loaded,
            "args": self._init_args,
            "spec": self.spec,
            "episode": episode if self._was_reset else None,
        }

    def __setstate__(self, data: dict[str, Any]) -> None:
        self.__init__(data["loaded"], **data["args"])  # type: ignore[misc]
        self.spec = data.get("spec")
        episode = data.get("episode")
        if episode is None:
            return  # pickled before its first reset: so is the copy
        try:
            self._carry_over(episode)
        except Exception as exc:  # noqa: BLE001 - whatever went wrong, the copy must not step a half-restored episode
            self._was_reset = False
            self._not_carried = f"the episode it was pickled in could not be carried over ({type(exc).__name__}: {exc})"
            warnings.warn(
                f"visualenv: {self.program.spec.id}: {self._not_carried}; call reset() to start a new one",
                RuntimeWarning,
                stacklevel=2,
            )

    def _carry_over(self, episode: dict[str, Any]) -> None:
        """The episode of the pickled env, put in place (see :meth:`__getstate__`)."""
        # the model fields a reset wrote (reacher's target)
        if episode.get("model") is not None and self._sim is not None:
            restore_fields(self._sim.model, episode["model"])
        self._set_physics_state(episode["physics"])
        self._state = tuple(episode["state"])
        self._steps, self._fired, self._done, self._success = (
            episode["steps"],
            episode["fired"],
            episode["done"],
            episode["success"],
        )
        self._np_random, self._np_random_seed = episode["np_random"], episode["np_random_seed"]
        self._legacy_random = episode.get("legacy_random")
        self._random.generator = self._legacy_random if self._legacy_random is not None else self._np_random
        self._sensor_rng = episode["sensor_rng"]
        self._distractions = episode.get("distractions", self._distractions)
        if episode["action_space_rng"] is not None:
            restore_space_generator(self.action_space, episode["action_space_rng"])
        self._last_obs = episode["last_obs"]
        self._was_reset = True

    def _physics_state(self) -> np.ndarray | None:
        """MuJoCo's full integration state of a physics spec (None without physics)."""
        return None if self._sim is None else integration_state(self._sim.data)

    def _set_physics_state(self, state: np.ndarray | None) -> None:
        """Put MuJoCo's integration state back, then ``mj_forward`` (the poses a render reads)."""
        if (state is None) != (self._sim is None):
            raise ValueError("the pickled env and its copy disagree on physics")
        if self._sim is None or state is None:
            return
        mujoco, model = self._sim.mujoco, self._sim.model
        signature = mujoco.mjtState.mjSTATE_INTEGRATION
        if state.shape != (mujoco.mj_stateSize(model, signature),):
            raise ValueError(
                f"MuJoCo's state has {state.size} values, this MuJoCo ({mujoco.__version__}) expects "
                f"{mujoco.mj_stateSize(model, signature)}"
            )
        mujoco.mj_setState(model, self._sim.data, state, signature)
        mujoco.mj_forward(model, self._sim.data)
