"""N envs in one process and one Blender scene: :class:`BatchedVectorEnv`.

The dynamics of all envs step at once as numpy columns (the program's
vectorised step, :mod:`visualenv.compiler.batch_step`), and one Cycles call per
camera renders every env's observation as a tile of one image
(:class:`~visualenv.render.blender.batch.renderer.BatchedBlenderRenderer`). A batch
of one steps and renders as one env does: its lane steps it, and one env's renderer draws it.
This module is the step; what the envs
show (observations, the binding table, the human grid) is
:class:`~visualenv.env.batch_observations.BatchObservations`'s.

Env i of a batch reset with seed s is env ``visualenv.make`` reset with seed
s + i: each env keeps its own random generator (a state-only
:class:`~visualenv.env.visual_env.VisualEnv`, its "lane") for the draws of
``reset``. A lane also steps its env alone when the vectorised step cannot:
a spec whose step draws random numbers or calls ``dynamics.python``, an env
whose result the episode's rules refuse (not finite, or past float32 in a
state-only observation) or whose action is not finite, and every env of a step
in which an operation met a value Python raises on (the lane then returns the
same value, or the located fault, exactly as one env would). The rules themselves
(endings, truncation, success, milestones, info, faults) are one env's:
:class:`~visualenv.env.episode.EpisodeRules`. A fault raised names its env:
``env 3: <what env 3 alone raises>`` (:attr:`StepError.env <visualenv.errors.StepError>`).

A physics spec's batch steps every env's MjData in one call and reads the
model's names as columns (:class:`~visualenv.physics.batch.BatchSimulation`);
an env whose result is not finite, or whose simulation blew up, replays its step
in its lane without stepping MuJoCo again, to the same value or located fault.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Any, Mapping

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from visualenv.compiler.physics import BEFORE
from visualenv.compiler.program import BatchFunctions, Program
from visualenv.compiler.render_plan import checked_options, observation_space
from visualenv.compiler.batch_functions import float_errors
from visualenv.env.batch_observations import BatchObservations
from visualenv.env.construction import (
    camera_sensors,
    episode_distractions,
    episode_length,
    program_for,
    uses_camera,
)
from visualenv.env.episode import EpisodeRules
from visualenv.env.human import HumanDisplay
from visualenv.env.visual_env import VisualEnv
from visualenv.errors import StepError
from visualenv.render.base import RendererOptions
from visualenv.render.batch_limits import check_batchable
from visualenv.render.profile import Profile
from visualenv.spec.loader import LoadedSpec
from visualenv.spec.options import distraction_settings, model_file

#: the renderer class of a batch, as ``module:attribute`` (imported on first render, so state-only batches never load bpy)
BATCH_BACKEND = "visualenv.render.blender.batch.renderer:batch_renderer"


@dataclass
class StepResults:
    """What one step gives each env, written in place by the vectorised step and by the lanes."""

    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray

    @classmethod
    def empty(cls, n: int) -> StepResults:
        return cls(np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))

    def clear(self) -> None:
        self.rewards[:], self.terminated[:], self.truncated[:] = 0.0, False, False


class BatchedVectorEnv(BatchObservations, gym.vector.VectorEnv):
    """`num_envs` copies of a spec's env, stepped together in this process.

    Spaces are those of ``visualenv.make(spec)`` batched: observations
    ``(N, H, W, C)`` uint8 (a Dict of those for several cameras), or
    ``(N, n)`` float32 state vectors with ``render=False``; actions ``(N,)``
    for discrete specs, ``(N, k)`` for continuous ones.

    Rewards, ``terminated`` and ``truncated`` are per env. ``info`` holds, per
    env (Gymnasium's vector layout, each key with its ``_key`` mask):
    ``state`` (a dict of arrays, each variable with its ``_name`` mask, as Sync/AsyncVectorEnv
    nest a dict), ``steps``, ``outcome``, ``milestones`` and
    ``is_success``; an env ended by a fault under ``on_fault: terminate`` has its
    message in ``error`` (the message one env gives). Under ``on_fault: raise``
    the fault of the first env that faulted is raised, prefixed ``env i:``.

    Episodes are truncated after the spec's ``max_steps``, or ``max_episode_steps`` when given
    (``gymnasium.make_vec`` passes the id's), with ``info["outcome"] == "max_steps"``. With an
    ``action_repeat`` of k (the spec's, or the option's), each step is k of the spec's steps per env, as
    one env's: rewards summed, stopped where the env's episode ends, one render.

    Autoreset follows Gymnasium 1.x: ``autoreset_mode`` ``NEXT_STEP`` (the
    default: the step after an episode's end resets that env, ignoring its
    action) or ``SAME_STEP`` (the env is reset at once; the last observation of
    the ended episode is in ``info["final_obs"]``, its info in
    ``info["final_info"]``, as SB3's VecEnv expects; only the reset envs are
    rendered a second time).

    Distractions (the spec's ``distractions`` or the option's, docs/distractions.md) are drawn per env: env i draws
    its own from a generator its lane's seed starts, as env i alone draws them (at each of its resets, and every step
    when dynamic), and its tile shows them (:mod:`visualenv.render.blender.batch.distraction_draws`).

    ``render_mode="human"`` shows a grid of the observations live after every reset and step on the registered display
    (:mod:`visualenv.env.human`: the viewer's local web page) and ``render()`` returns None.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array", "human"], "render_fps": 30}

    def __init__(
        self,
        spec: str | os.PathLike[str] | LoadedSpec | Program,
        num_envs: int,
        *,
        render: bool | None = None,
        params: dict[str, Any] | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        render_mode: str | None = None,
        renderer_options: RendererOptions | Mapping[str, Any] | None = None,
        backend: str = BATCH_BACKEND,
        max_episode_steps: int | None = None,
        action_repeat: int | None = None,
        distractions: float | str | Mapping[str, Any] | None = None,
        trust_code: bool = False,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer of at least 1, got {num_envs!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self._renderer: Any = None
        #: the step's phase timings, recorded while set (visualenv bench); the renderer's own are its ``profile``
        self.profile: Profile | None = None
        modes = {m.name: m for m in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)}
        mode = autoreset_mode.name if isinstance(autoreset_mode, AutoresetMode) else str(autoreset_mode).upper()
        if mode not in modes:
            raise ValueError(f"autoreset_mode must be one of {', '.join(modes)}, got {autoreset_mode!r}")
        self.autoreset_mode = modes[mode]
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        program = program_for(spec, params, trust_code)
        self.program = program
        self.num_envs = n = int(num_envs)
        observation = program.spec.observation
        self.uses_camera = uses_camera(program, render)
        if render_mode == "human" and not self.uses_camera:
            raise ValueError(
                "render_mode='human' shows a grid of the observations, and a state-only batch has none: "
                "use render_mode='rgb_array' for the views"
            )
        self._display: HumanDisplay | None = None  # render_mode="human": where the grid is shown, opened at first
        #: what each env's observation shows changed per episode (the spec's ``distractions``, or the option's); None: nothing
        self.distractions = (
            distraction_settings(
                distractions, program.spec.distractions, model_file(program.spec), program.loaded.base_dir
            )
            if self.uses_camera
            else None
        )
        length = episode_length(program, max_episode_steps, action_repeat)
        #: the spec's steps per step() (dm_control's action repeat), each with the same action: as one env's
        self.action_repeat = length.action_repeat
        step_limit_ = length.step_limit
        #: episodes are truncated after this many step() calls
        self.max_episode_steps = length.max_episode_steps
        #: the episode's endings, success, info and faults, as each env alone has them (visualenv.env.episode)
        self.rules = EpisodeRules(program, step_limit_, observes_state=not self.uses_camera and program.physics is None)
        # the batch repeats the action; a batch of one steps as one env, by its lane, which repeats it
        lane_steps, lane_repeat = (max_episode_steps, action_repeat) if n == 1 else (step_limit_, 1)
        self._lanes = [
            VisualEnv(program, render=False, max_episode_steps=lane_steps, action_repeat=lane_repeat) for _ in range(n)
        ]
        #: a physics spec's simulations stepped and read together (None: each lane steps its own, or no physics)
        self._physics: Any = None
        self._pose_arrays: list[tuple] | None = None
        # what the pose arrays view: each env's MjData, or MuJoCo's batch's rows
        self._pose_sources: list[Any] | None = None
        if n == 1:  # numpy's cost per column call is the same for one env as for a thousand: one env's step is cheaper
            self._batch = BatchFunctions(None, None)
        elif program.physics is not None:
            physics = program.physics.batch([lane.simulation for lane in self._lanes])
            self._batch = program.batch_functions(physics)
            if self._batch.step is not None:
                self._physics = physics
            else:
                physics.close()
        else:
            self._batch = program.batch_functions()
        self._renderer_options = checked_options(renderer_options)
        if self.uses_camera and backend == BATCH_BACKEND:
            check_batchable(self._render_plan(), n)  # refused now, not at the first render
        self._backend = backend
        single = self._lanes[0]
        self.single_action_space = single.action_space
        self.action_space = batch_space(single.action_space, n)
        self.single_observation_space = observation_space(observation) if self.uses_camera else single.observation_space  # type: ignore[arg-type]
        self.observation_space = batch_space(self.single_observation_space, n)
        self._sensors = camera_sensors(observation, self.single_observation_space) if self.uses_camera else {}
        names = program.state_names
        self._state = np.zeros((len(names), n))
        self._steps = np.zeros(n, dtype=np.int64)
        self._fired = np.zeros(n, dtype=np.int64)
        self._success = np.zeros(n, dtype=bool)
        self._outcome = np.full(n, None, dtype=object)  # info["outcome"] of each env's last step
        self._errors = np.full(n, None, dtype=object)
        self._autoreset = np.zeros(n, dtype=bool)
        self._was_reset = False
        #: each env's distractions, drawn from its own generator as the env alone draws them (its lane's seed)
        self._distractions = (
            [episode_distractions(program, self.distractions, distractions is not None) for _ in range(n)]
            if self.distractions is not None
            else []
        )

    @property
    def lanes(self) -> list[VisualEnv]:
        """Each env's state-only single env, its MuJoCo data whole (MuJoCo's batch API steps copies of its own: handed out, they
        are brought up to date first)."""
        if self._physics is not None:
            for i in range(self.num_envs):
                self._physics.sync(i)
        return self._lanes

    # -- Gymnasium API ------------------------------------------------------------------------------

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset every env; env i gets seed ``seed + i`` (or ``seed[i]``)."""
        seeds = (
            seed
            if isinstance(seed, (list, tuple))
            else [None if seed is None else seed + i for i in range(self.num_envs)]
        )
        if len(seeds) != self.num_envs:
            raise ValueError(f"reset got {len(seeds)} seeds for {self.num_envs} envs")
        for i, s in enumerate(seeds):
            self._reset_lane(i, seed=s, options=options)
        self._autoreset[:] = False
        self._was_reset = True
        obs = self._observe()
        if self.render_mode == "human":
            self._show(obs)
        return obs, self._info(np.ones(self.num_envs, dtype=bool))

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._was_reset:
            raise gym.error.ResetNeeded("call reset() before step(): the state is set by reset (Gymnasium's order)")
        actions = self._check_actions(actions)
        n = self.num_envs
        results = StepResults.empty(n)
        rewards, terminated, truncated = results.rewards, results.terminated, results.truncated
        resetting = self._autoreset.copy()
        stepping = ~resetting
        if stepping.any():
            start = time.perf_counter()
            self._repeat(actions, stepping, results)
            if self.profile is not None:
                self.profile.add("dynamics", time.perf_counter() - start)
        for i in np.flatnonzero(stepping & (self._errors == None)) if self._distractions else ():  # noqa: E711 - as one env, not after a fault
            self._distractions[i].advance()
        for i in np.flatnonzero(resetting):
            self._reset_lane(int(i))
        done = terminated | truncated
        final: tuple[Any, dict[str, Any]] | None = None
        if self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            final = (self._observe(), self._info(done))
            ended = np.flatnonzero(done)
            for i in ended:
                self._reset_lane(int(i))
            self._autoreset[:] = False
            obs = _with_rows(final[0], ended, self._observe(ended))  # only the reset envs are rendered again
        else:
            self._autoreset = done
            obs = self._observe()
        info = self._info(np.ones(n, dtype=bool))
        if final is not None:
            # one object per env, even when every env ended (np.array would stack them)
            info["final_obs"] = np.empty(n, dtype=object)
            for i in np.flatnonzero(done):
                info["final_obs"][i] = _select(final[0], int(i))
            info["_final_obs"] = done
            info["final_info"] = final[1]
            info["_final_info"] = done
        if self.render_mode == "human":
            self._show(obs)
        return obs, rewards, terminated, truncated, info

    def render(self) -> tuple[np.ndarray, ...] | None:  # type: ignore[override]
        """Each env's high-resolution RGB view (render_mode="rgb_array"), as Gymnasium's vector envs return them: a tuple.

        One Cycles call renders every env's view as a tile (several past the image limit).
        A view uses other render settings than the observations, so the step after it
        re-synchronises the scene: for recording now and then, not every step.
        """
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; make the batch with render_mode='rgb_array'")
            return None
        if self.render_mode == "human":  # every step is already shown
            return None
        if not self.uses_camera:
            raise gym.error.Error("a state-only batch (render=False) has no Blender scene to render a view of")
        return tuple(self.renderer.render_view(self._frames()))

    def close_extras(self, **kwargs: Any) -> None:
        if (display := getattr(self, "_display", None)) is not None:
            display.close()
            self._display = None
        if getattr(self, "_physics", None) is not None:
            self._physics.close()
        if getattr(self, "_renderer", None) is not None:
            self._renderer.close()
            self._renderer = None

    # -- the step -----------------------------------------------------------------------------------

    def _repeat(self, actions: np.ndarray, stepping: np.ndarray, results: StepResults) -> None:
        """The action repeat: each stepping env's spec step ``action_repeat`` times with its action, its rewards summed,
        stopping where its episode ends; a step a fault ended has no reward (as one env's)."""
        if self.num_envs == 1:  # its lane is the env alone, repeating the action itself
            self._step_lane(0, actions[0], results)
            return
        if self.action_repeat == 1:
            self._advance(actions, stepping, results)
            return
        going = stepping.copy()
        each = StepResults.empty(self.num_envs)
        for _ in range(self.action_repeat):
            each.clear()
            self._advance(actions, going, each)
            results.rewards[going] += each.rewards[going]
            results.terminated |= each.terminated
            results.truncated |= each.truncated
            going &= ~(each.terminated | each.truncated)
            if not going.any():
                break
        results.rewards[stepping & (self._errors != None)] = 0.0  # noqa: E711 - element-wise: ended by a fault (on_fault: terminate)

    def _advance(self, actions: np.ndarray, stepping: np.ndarray, results: StepResults) -> None:
        """Every stepping env's step at once, then the lanes of those the vectorised step could not do.

        An env goes to its lane when its result is one the episode's rules refuse (NaN, an infinity,
        past float32), its simulation blew up, or its action is not finite; every env does when an
        operation of the step met a value Python raises on (float_errors: a division by zero, log(0)...,
        whose env the element-wise code cannot say, and whose result numpy may have clipped into a number).
        """
        alone = stepping.copy()
        rewards, terminated, truncated = results.rewards, results.terminated, results.truncated
        step = self._batch.step
        if step is not None:
            unfinite = None  # the envs whose continuous action is not finite, if any
            if self.program.discrete is None and not np.isfinite(actions).all():
                unfinite = ~np.isfinite(actions).all(axis=1)
            columns = tuple(self._state)
            action = tuple(actions.T.astype(np.float64)) if self.program.discrete is None else actions
            with float_errors() as errors:
                if self._physics is not None:
                    self._physics.active = np.flatnonzero(stepping)
                    self._physics.watch(errors, unfinite)
                state, reward, outcome, fired = step(columns, action, self._steps, self._fired)
            n = self.num_envs
            state = np.array([np.broadcast_to(v, (n,)) for v in state]) if state else self._state.copy()
            reward = np.broadcast_to(np.asarray(reward, dtype=np.float64), (n,))
            outcome = np.broadcast_to(np.asarray(outcome, dtype=np.int64), (n,))
            fired = np.broadcast_to(np.asarray(fired, dtype=np.int64), (n,))
            unfit = self.rules.unfit(state, reward) | bool(errors)
            if self._physics is not None:
                unfit |= self._physics.blown
            if unfinite is not None:
                unfit |= unfinite
            ok = stepping & ~unfit
            alone = stepping & unfit
            self._state[:, ok] = state[:, ok]
            self._steps[ok] += 1
            self._success[ok] = self.rules.successes(self._success[ok], outcome[ok], fired[ok] & ~self._fired[ok])
            self._fired[ok] = fired[ok]
            rewards[ok] = reward[ok]
            terminated[ok], truncated[ok], self._outcome[ok] = self.rules.endings(outcome[ok], self._steps[ok])
            self._errors[ok] = None
        for i in np.flatnonzero(alone):
            if self._physics is not None:
                self._replay_lane(int(i), actions[i], results)
            else:
                self._step_lane(int(i), actions[i], results)
        if self._physics is not None:
            self._physics.kept.clear()

    def _replay_lane(self, i: int, action: Any, results: StepResults) -> None:
        """Env i's step, whose MuJoCo step the batch took, run again by its lane: its result or its located fault, as env i alone."""
        physics, simulation = self._physics, self._lanes[i].simulation
        try:
            with simulation.replaying(physics.recorded(i, (BEFORE,)), bool(physics.blown[i])):
                self._step_lane(i, action, results)
        finally:
            if not simulation.replay_stepped:  # it faulted before its MuJoCo step: alone, its data was not stepped
                physics.put_back(i)

    def _step_lane(self, i: int, action: Any, results: StepResults) -> None:
        """Env i stepped by its lane: the scalar step, with its checks and faults."""
        lane = self._lane_at(i)
        try:
            _, reward, term, trunc, info = lane.step(action.item() if self.program.discrete is not None else action)
        except StepError as err:
            raise err.in_env(i) from None
        self._state[:, i] = [info["state"][n] for n in self.program.state_names]
        self._steps[i], self._fired[i], self._success[i] = lane.steps, lane.fired, info["is_success"]
        results.rewards[i], results.terminated[i], results.truncated[i] = reward, term, trunc
        self._outcome[i] = info["outcome"]
        self._errors[i] = info.get("error")

    def _lane_at(self, i: int) -> VisualEnv:
        """Env i's lane, put where env i is in its episode."""
        lane = self._lanes[i]
        if self._physics is not None:
            self._physics.sync(i)
        lane.restore(self._state[:, i], int(self._steps[i]), int(self._fired[i]), bool(self._success[i]))
        return lane

    def _reset_lane(self, i: int, *, seed: int | None = None, options: dict[str, Any] | None = None) -> None:
        try:
            self._state[:, i] = self._lanes[i].begin_episode(seed=seed, options=options)
        except StepError as err:
            raise err.in_env(i) from None
        if self._physics is not None:
            self._physics.refresh(i)
        if self._distractions:
            self._distractions[i].begin(self._lanes[i].np_random, seed is not None)
        self._steps[i] = 0
        self._fired[i] = 0
        self._success[i] = False
        self._outcome[i] = None
        self._errors[i] = None

    def _check_actions(self, actions: Any) -> np.ndarray:
        array = np.asarray(actions)
        if array.dtype.kind not in "iuf" or array.dtype == np.bool_:
            raise TypeError(f"actions must be numbers: the action space is {self.action_space}")
        if array.shape != self.action_space.shape:
            raise ValueError(
                f"actions of shape {array.shape} for {self.num_envs} envs: the action space is {self.action_space}"
            )
        if self.program.discrete is not None:
            if array.dtype.kind == "f" and not np.all(array == np.round(array)):
                raise TypeError(f"discrete actions must be integers, got {actions!r}")
            array = array.astype(np.int64)
            if ((array < 0) | (array >= self.program.discrete)).any():
                raise ValueError(f"actions {actions!r} out of range: the action space is {self.action_space}")
        return array

    def _info(self, mask: np.ndarray) -> dict[str, Any]:
        return self.rules.batch_info(
            self._state, self._steps, self._outcome, self._fired, self._success, self._errors, mask
        )


def _select(obs: Any, i: int) -> Any:
    return {k: v[i] for k, v in obs.items()} if isinstance(obs, dict) else obs[i]


def _with_rows(obs: Any, rows: np.ndarray, new: Any) -> Any:
    """A copy of the batch observation `obs` with its `rows` replaced by `new` (arrays or dicts of them)."""
    if isinstance(obs, dict):
        return {k: _with_rows(v, rows, new[k]) for k, v in obs.items()}
    out = obs.copy()
    out[rows] = new
    return out


#: the keywords of make_batched (and make_vec(batched=True)) that are the batch's own; the rest are renderer options
BATCH_OPTIONS = (
    "render",
    "params",
    "autoreset_mode",
    "render_mode",
    "max_episode_steps",
    "action_repeat",
    "distractions",
    "trust_code",
)


def make_batched(target: str | os.PathLike[str], num_envs: int = 1, **kwargs: Any) -> BatchedVectorEnv:
    """A batch from keyword options as ``visualenv.make`` takes them: :class:`BatchedVectorEnv`'s (render, params,
    autoreset_mode, render_mode, max_episode_steps) and the renderer options (``device``, ``threads``, ``samples``, ``noise``, ``readback``).

    Also the vector entry point of the registered ids: ``gymnasium.make_vec("visualenv/<Id>", N, vectorization_mode="vector_entry_point")``,
    which passes the id's ``max_episode_steps`` (the spec's max_steps, or the one given to make_vec).
    ``trust_code=True``: the spec's ``dynamics.python`` may be imported (docs/security.md).
    """
    own = {k: kwargs.pop(k) for k in BATCH_OPTIONS if k in kwargs}
    return BatchedVectorEnv(target, num_envs, renderer_options=kwargs, **own)
