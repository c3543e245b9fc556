"""The Gymnasium env a compiled spec becomes."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from visualenv.compiler.program import Program
from visualenv.compiler.render_plan import checked_options, observation_space, views_plan
from visualenv.errors import StepError, did_you_mean
from visualenv.expr.functions import RandomSource
from visualenv.env.construction import (
    camera_sensors,
    episode_distractions,
    episode_length,
    program_for,
    uses_camera,
)
from visualenv.env.episode import EpisodeRules
from visualenv.env.human import HumanDisplay, open_human_display
from visualenv.env.pickling import PicklingEnv
from visualenv.physics.conventions import legacy_stream
from visualenv.render.base import BLENDER_BACKEND, Renderer, RendererOptions, create_renderer
from visualenv.render.frames import Frames
from visualenv.render.sensor import SensorModel, sensor_generator
from visualenv.spec.loader import LoadedSpec
from visualenv.spec.options import distraction_settings, model_file

#: the keys reset(options=...) understands
RESET_OPTIONS = ("state",)


class VisualEnv(PicklingEnv):
    """A Gymnasium env compiled from a visualenv spec.

    ## Observation space
    With a renderer (the default when the spec has an ``observation``): what the
    spec's camera sees, ``Box(0, 255, (H, W, C), uint8)`` with C = 1 for
    grayscale or depth and 3 for RGB; several cameras give a ``Dict`` of those.
    Without (``render=False``, or no ``observation`` in the spec): the state
    variables marked ``observe`` in declared order, a float32 ``Box`` of shape (n,);
    with ``physics``, ``physics.observe`` as an unbounded float64 ``Box``, as
    Gymnasium's MuJoCo envs observe (``model`` and ``data`` are then MuJoCo's).

    ## Action space
    ``Discrete(n)`` for ``actions.discrete`` (action i sets its inputs for the
    step); ``Box(low, high, (n,), float32)`` for ``actions.continuous``.

    ## Rewards
    The spec's ``reward`` every step, plus the ``reward`` of each outcome that fires.

    ## Episode end
    Terminated or truncated by the first ending outcome whose ``when`` holds
    after the update (in spec order); truncated after ``max_steps`` steps
    (or ``max_episode_steps``, Gymnasium's TimeLimit, when given).
    ``info`` has ``state`` (all variables), ``outcome`` (the name of the outcome
    that ended the episode, ``"max_steps"``, or None), ``milestones`` and
    ``is_success``.

    ## Action repeat
    With ``action_repeat`` k (the spec's, or the option's), one ``step()`` makes
    k of the spec's steps with the same action, as dm_control's benchmarks do:
    their rewards summed, one observation (one render), stopping early at the
    episode's end. ``max_steps``, ``steps`` and ``info["steps"]`` count the
    spec's steps; ``max_episode_steps`` counts ``step()`` calls.

    ## Runtime faults
    A non-finite state or reward, a division by zero, a math domain error or
    (state-only, without physics) a state past float32's range raises
    :class:`~visualenv.errors.StepError` naming the expression, its spec line
    and the values; with ``on_fault: terminate`` the episode ends instead
    (reward 0, terminated, ``info["outcome"] == "error"``) and
    ``info["error"]`` holds the message. These rules, and those of the episode
    end, are :class:`~visualenv.env.episode.EpisodeRules`, which a batch's envs follow too.

    ## Pickling
    A pickled env goes on with its episode: the copy's next steps are the original's
    (state, step count, random generators, MuJoCo's state; the scene is posed from
    the state). Where the episode cannot be carried over, the unpickled copy warns
    and asks for ``reset()`` (:mod:`visualenv.env.pickling`).

    ## Render modes
    ``"rgb_array"``: ``render()`` returns the high-resolution view (``render.view``). ``"human"``: every reset and
    step is shown live on the registered display (:mod:`visualenv.env.human`: the viewer's local web page, whose URL
    is printed once) and ``render()`` returns None, as Gymnasium specifies.

    ## Python dynamics
    A spec whose ``dynamics.python`` names a module is made only with ``trust_code=True``: importing the module runs
    its code (docs/security.md). Without it, a :class:`~visualenv.errors.SpecError` located at that line says so.

    ## Renderer backend
    ``backend`` names the renderer class as ``module:attribute`` (default:
    Blender), loaded on first render; a test can plug in a fake renderer to
    check logic that does not depend on pixels.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 30}

    def __init__(
        self,
        spec: str | Path | LoadedSpec | Program,
        *,
        render: bool | None = None,
        render_mode: str | None = None,
        params: dict[str, Any] | None = None,
        renderer_options: RendererOptions | Mapping[str, Any] | None = None,
        backend: str = BLENDER_BACKEND,
        max_episode_steps: int | None = None,
        action_repeat: int | None = None,
        distractions: float | str | Mapping[str, Any] | None = None,
        trust_code: bool = False,
    ) -> None:
        super().__init__()
        program = program_for(spec, params, trust_code)
        self._init_args = {
            "render": render,
            "render_mode": render_mode,
            "params": params,
            "renderer_options": renderer_options,
            "backend": backend,
            "max_episode_steps": max_episode_steps,
            "action_repeat": action_repeat,
            "distractions": distractions,
            "trust_code": trust_code,
        }
        self.program = program
        s = program.spec
        length = episode_length(program, max_episode_steps, action_repeat)
        #: the spec's steps per step() (dm_control's action repeat), each with the same action
        self.action_repeat: int = length.action_repeat
        self._step_limit = length.step_limit
        #: episodes are truncated after this many step() calls: the spec's max_steps (over the action repeat), or Gymnasium's
        self.max_episode_steps: int = length.max_episode_steps
        # no camera to render a view with: no render mode (check_env reads it)
        if s.observation is None and not s.render.view.camera:
            self.metadata = {**self.metadata, "render_modes": []}
            if render_mode is not None:
                raise ValueError(
                    f"render_mode={render_mode!r} needs a camera: the spec has no 'observation' and no 'render.view.camera'"
                )
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.uses_camera = uses_camera(program, render)
        self._backend = backend
        self._renderer_options = checked_options(renderer_options)
        self._renderer: Renderer | None = None
        self._display: HumanDisplay | None = None  # render_mode="human": where the steps are shown, opened at the first
        self._last_obs: Any = None  # the latest camera observation, returned again if a fault ends the episode
        self._random = RandomSource()
        #: dm_control's task stream (a spec with ``physics.convention: dm_control``): RandomState(seed), continued across episodes
        self._legacy_random: np.random.RandomState | None = None
        #: a physics spec's own MuJoCo simulation; ``model`` and ``data`` are its MjModel and MjData, as in Gymnasium's MujocoEnv
        self._sim = program.physics.simulation() if program.physics is not None else None
        self.model: Any = self._sim.model if self._sim is not None else None
        if program.physics is not None:  # videos play at the simulation's speed, as Gymnasium's MuJoCo envs say
            self.metadata = {
                **self.metadata,
                "render_fps": max(1, int(round(1.0 / (program.physics.dt * self.action_repeat)))),
            }
        self.data: Any = self._sim.data if self._sim is not None else None
        self._fns = program.functions(self._random, self._sim)
        #: the episode's endings, success, info and faults (shared with the batch: visualenv.env.episode)
        self._rules = EpisodeRules(
            program, self._step_limit, observes_state=not self.uses_camera and program.physics is None
        )
        self._faults = self._rules.faults
        self._state: tuple[float, ...] = tuple(0.0 for _ in program.state_names)
        self._steps = 0
        self._fired = 0
        self._done = False
        self._success = False
        self._was_reset = False  # step() before the first reset() raises, as Gymnasium's OrderEnforcing does
        self._not_carried: str | None = None  # why an unpickled copy could not go on with its episode
        if program.discrete is not None:
            self.action_space = spaces.Discrete(program.discrete)
        else:  # a model without actuators and a spec without actions: an empty Box (the model moves on its own)
            lows, highs = np.array(program.continuous, np.float32).reshape(-1, 2).T
            self.action_space = spaces.Box(lows, highs, dtype=np.float32)
        if self.uses_camera:
            self.observation_space = observation_space(s.observation)  # type: ignore[arg-type]
        elif program.physics is not None:  # Gymnasium's MuJoCo envs observe float64 vectors, unbounded
            self.observation_space = spaces.Box(-np.inf, np.inf, (program.physics.observe_size,), np.float64)
        else:
            n = len(program.observed)
            big = np.finfo(np.float32).max  # finite bounds: check_env warns about infinite ones
            self.observation_space = spaces.Box(-big, big, (n,), np.float32)
        #: each camera's sensor noise, from a generator seeded at reset from the env's seed (lanes of a batch keep one too)
        self._sensors = camera_sensors(s.observation, self.observation_space) if self.uses_camera else {}
        self._has_sensor = any(view.sensor is not None for view in views_plan(s.observation).values())
        self._sensor_rng: np.random.Generator | None = None
        self._observed = program.observed
        #: what the observation shows changed per episode (the spec's ``distractions``, or the option's); None: nothing
        self.distractions = distraction_settings(distractions, s.distractions, model_file(s), program.loaded.base_dir)
        self._distractions = (
            episode_distractions(program, self.distractions, distractions is not None)
            if self.distractions is not None and self.uses_camera
            else None
        )

    # -- Gymnasium API ------------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        self.begin_episode(seed=seed, options=options)
        obs, info = self._observe(), self._rules.info(self.state, 0, None, 0, False)
        if self.render_mode == "human":
            self._show(None, info)
        return obs, info

    def begin_episode(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[float, ...]:
        """:meth:`reset` without its observation and info: the initial state, drawn and checked.

        A batch's lane starts its env's episodes with it (the batch observes all its envs at once).
        """
        super().reset(seed=seed)
        self._random.generator = self._reset_generator(seed)
        if self._has_sensor and (seed is not None or self._sensor_rng is None):
            self._sensor_rng = sensor_generator(self.np_random)
        if self._distractions is not None:
            self._distractions.begin(self.np_random, seed is not None)
        if self._sim is not None:
            self._sim.reset(self.program.physics.keyframe)  # type: ignore[union-attr]
        try:
            state = self._fns.init()
        except (ArithmeticError, ValueError) as exc:
            raise self._faults.raised("init", exc, {}, self._steps) from None
        given = self._reset_options(options)
        if given:
            names = self.program.state_names
            values = list(state)
            for key, value in given.items():
                values[names.index(key)] = value
            state = tuple(values)
        self._steps = 0
        self._rules.check_reset(state, self._steps)
        self._state = tuple(float(v) for v in state)
        self._steps = 0
        self._fired = 0
        self._done = False
        self._success = False
        self._was_reset = True
        self._not_carried = None
        return self._state

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """The action, the generated step (checked, not yet committed), the commit, the episode's end, the observation."""
        if not self._was_reset:
            raise ResetNeeded(
                f"call reset() before step(): {self._not_carried or 'the state is set by reset'} (Gymnasium's order)"
            )
        a = self._action(action)
        rules = self._rules
        total = 0.0
        for _ in range(self.action_repeat):  # dm_control's action repeat: the rewards summed, one observation
            try:
                state, reward, outcome, fired = self._advance(a)
            except (ArithmeticError, ValueError, StepError) as exc:
                return self._fault_in_step(exc, a)
            self._success = rules.succeeded(self._success, outcome, fired & ~self._fired)
            self._state, self._fired = state, fired
            self._steps += 1
            total += reward
            terminated, truncated, name = rules.ending(outcome, self._steps)
            if terminated or truncated:
                break
        reward = total
        if self._distractions is not None:
            self._distractions.advance()
        try:
            obs = self._observe()
        except StepError as err:  # an actor binding of the new state faulted: nothing to render
            return self._fault_in_observation(err)
        info = rules.info(self.state, self._steps, name, self._fired, self._success)
        if self.render_mode == "human":
            self._show(float(reward), info)
        return obs, float(reward), terminated, truncated, info

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """The high-resolution RGB view (render_mode="rgb_array"); None without a render mode, and in "human" mode,
        whose every step is already shown."""
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; make the env with render_mode='rgb_array'")
            return None
        if self.render_mode == "human":
            return None
        return self._view()

    def close(self) -> None:
        if self._display is not None:
            self._display.close()
            self._display = None
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()

    # -- the step, in order ---------------------------------------------------------------------------

    def _action(self, action: Any) -> Any:
        """The action as the generated step takes it: a discrete index, or one float per continuous input."""
        n = self.program.discrete
        return self._discrete_action(action, n) if n is not None else self._continuous_action(action)

    def _advance(self, action: Any) -> tuple:
        """The generated step on the current state: (state, reward, outcome, fired), checked by the episode's rules
        (a located StepError for NaN, an infinity, or a state the float32 observation cannot hold); nothing is committed yet."""
        old = self._state
        result = self._fns.step(old, action, self._steps, self._fired)
        self._rules.check(result[0], result[1], lambda: self._values(old, action), self._steps)
        return result

    def _fault_in_step(self, exc: BaseException, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """A fault computing the step, which leaves the state as it was: raised located, or (``on_fault: terminate``) the episode's end."""
        err = (
            exc
            if isinstance(exc, StepError)
            else self._faults.raised("step", exc, self._values(self._state, action), self._steps)
        )
        if self._rules.raises:
            raise err from None
        self._steps += 1
        return self._end_on_fault(err, self._last_obs if self.uses_camera else self._observe())

    def _fault_in_observation(self, err: StepError) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """A binding of the committed state faulted before the render: raised, or the episode ends on the last frame."""
        if self._rules.raises:
            raise err
        return self._end_on_fault(err, self._last_obs)

    # -- actions and reset options --------------------------------------------------------------------

    def _discrete_action(self, action: Any, n: int) -> int:
        """An int, a numpy integer or a 0-d integer array (as SB3 passes them); a bool, float or text is refused."""
        value = action[()] if isinstance(action, np.ndarray) and action.shape == () else action
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
            raise TypeError(
                f"action {action!r} is not an integer: the action space is {self.action_space}, actions 0 to {n - 1}"
            )
        if not 0 <= value < n:
            raise ValueError(f"action {action!r} is out of range: the action space is {self.action_space}")
        return int(value)

    def _continuous_action(self, action: Any) -> tuple[float, ...]:
        """One number per input (any numeric array or list of the right size); text or bools are refused."""
        values = np.asarray(action)
        if values.dtype.kind not in "iuf":
            raise TypeError(f"action {action!r} is not an array of numbers: the action space is {self.action_space}")
        a = tuple(values.astype(np.float64).reshape(-1).tolist())
        if len(a) != len(self.program.continuous):
            raise ValueError(
                f"action has {len(a)} values, expected {len(self.program.continuous)}: the action space is {self.action_space}"
            )
        return a

    def _reset_generator(self, seed: int | None) -> Any:
        """The generator this episode's draws come from: Gymnasium's ``np_random``, or dm_control's stream.

        A spec with ``physics.convention: dm_control`` draws as ``suite.load(..., task_kwargs={"random": seed})``
        does: ``RandomState(seed)`` at a seeded reset, the same stream continued by the next resets.
        """
        physics = self.program.physics
        if physics is None or physics.convention != "dm_control":
            return self.np_random
        if seed is not None or self._legacy_random is None:
            self._legacy_random = legacy_stream(seed, self.np_random)
        return self._legacy_random

    def _reset_options(self, options: dict[str, Any] | None) -> dict[str, float]:
        """The state values of ``options["state"]`` as floats; an unknown option or variable, or a value that is not a number, is an error."""
        if not options:
            return {}
        unknown = [key for key in options if key not in RESET_OPTIONS]
        if unknown:
            raise ValueError(
                f"unknown reset option {unknown[0]!r}"
                + did_you_mean(str(unknown[0]), RESET_OPTIONS).replace("names:", "options:")
            )
        given = options.get("state") or {}
        if not isinstance(given, Mapping):
            raise ValueError(f"options['state'] must map state variables to numbers, got {given!r}")
        names = self.program.state_names
        values: dict[str, float] = {}
        for key, value in given.items():
            if key not in names:
                raise KeyError(f"options['state'] has an unknown variable '{key}'" + did_you_mean(str(key), names))
            if isinstance(value, np.ndarray) and value.shape == ():
                value = value[()]
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise ValueError(f"options['state'][{key!r}]: expected a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"options['state'][{key!r}]: expected a finite number, got {value!r}")
            values[key] = float(value)
        return values

    # -- state access -------------------------------------------------------------------------------

    @property
    def state(self) -> dict[str, float]:
        """The current state by variable name."""
        return dict(zip(self.program.state_names, self._state))

    @property
    def steps(self) -> int:
        return self._steps

    @property
    def fired(self) -> int:
        """The milestones fired this episode, as bits in spec order."""
        return self._fired

    @property
    def simulation(self) -> Any:
        """A physics spec's :class:`~visualenv.physics.simulation.Simulation` (None without physics): a batch steps its lanes' together."""
        return self._sim

    def restore(self, state: Any, steps: int, fired: int, success: bool) -> None:
        """Put the env at a point of an episode: a batch hands one env to its lane to step it alone."""
        self._state = tuple(float(v) for v in state)
        self._steps, self._fired, self._success = steps, fired, success
        self._done = False
        self._was_reset = True

    @property
    def renderer(self) -> Renderer:
        """The renderer, built on first use (in the process that uses it)."""
        if self._renderer is None:
            self._renderer = create_renderer(self.program.render_plan(), self._backend, self._renderer_options)
        return self._renderer

    def apply_sensors(self, obs: Any, sensors: Mapping[str, SensorModel] | None = None) -> Any:
        """The observation (an array, or a dict by camera key) through each camera's sensor model, drawing from this env's sensor generator.

        A batch passes its own ``sensors`` (its lanes render nothing) and each env's frame to that env's lane.
        """
        sensors = self._sensors if sensors is None else sensors
        rng = self._sensor_rng
        assert rng is not None, "reset() seeds the sensor generator"
        if isinstance(obs, dict):
            return {key: sensors[key](frame, rng) if key in sensors else frame for key, frame in obs.items()}
        return next(iter(sensors.values()))(obs, rng)

    @property
    def segmentation_ids(self) -> dict[str, int]:
        """Id of each label (or unlabelled object name) in segmentation observations; 0 is the background. Builds the renderer.

        Empty when no observation camera has ``color: segmentation``.
        """
        if not self.uses_camera:
            return {}
        return dict(getattr(self.renderer, "segmentation_ids", {}))

    def binding_values(self) -> tuple:
        """The current values of every actor binding, in program.bindings order."""
        return self._bind()

    # -- internals --------------------------------------------------------------------------------

    def physics_observation(self) -> np.ndarray:
        """A physics spec's state-only observation of the current state (a batch asks each lane for its own)."""
        assert self._fns.observe is not None, "not a physics spec"
        return np.array(self._fns.observe(self._state, self._steps), dtype=np.float64)

    def frames(self) -> Frames:
        """What the renderer draws of this state: its binding values, MuJoCo's poses (live views of the simulation:
        :meth:`Frames.copy` keeps them), the episode's distraction."""
        poses = None if self._sim is None else (self.program.physics.poses(self._sim.data),)  # type: ignore[union-attr]
        drawn = self._distractions.current if self._distractions is not None else None
        return Frames((self._bind(),), poses, None if drawn is None else (drawn,))

    def _view(self) -> np.ndarray:
        """The high-resolution view of the current state."""
        return self.renderer.render_view(self.frames())[0]

    def _show(self, reward: float | None, info: dict[str, Any]) -> None:
        """render_mode="human": the observation, the values and the view (called only when shown) on the display."""
        if self._display is None:
            self._display = open_human_display()
        self._display.show(
            self.program.spec.id, self._last_obs if self.uses_camera else None, {"reward": reward, **info}, self._view
        )

    def _observe(self) -> Any:
        if self.uses_camera:
            frames = self.renderer.render(self.frames())
            obs = frames[0] if isinstance(frames, np.ndarray) else {key: value[0] for key, value in frames.items()}
            self._last_obs = self.apply_sensors(obs) if self._sensors else obs
            return self._last_obs
        return self.state_observation()

    def state_observation(self) -> np.ndarray:
        """What the env observes with ``render=False``, whatever it renders: a state-only teacher's input (`visualenv distill`)."""
        if self._fns.observe is not None:
            return self.physics_observation()
        state = self._state
        return np.array([state[i] for i in self._observed], dtype=np.float32)

    def _bind(self) -> tuple:
        """The actor binding values for the current state; a fault in them is a StepError, not a bare exception."""
        try:
            values = self._fns.bind(self._state, self._steps)
            total = sum(values)
        except (ArithmeticError, ValueError) as exc:
            raise self._faults.raised("bind", exc, self.state, self._steps) from None
        if total - total != 0:  # NaN or infinity somewhere
            self._faults.check_bindings(values, self.state, self._steps)
        return values

    def _end_on_fault(self, err: StepError, obs: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """``on_fault: terminate``: the episode ends with no reward; ``obs`` is the last one that could be made."""
        info = self._rules.fault_info(self.state, self._steps, self._fired, self._success, str(err))
        if self.render_mode == "human":
            self._show(0.0, info)
        return obs, 0.0, True, False, info

    def _values(self, state: tuple, action: Any) -> dict[str, Any]:
        """What a step's expressions read, for a fault's message: the state, each continuous input as given (before clipping), the action."""
        values: dict[str, Any] = dict(zip(self.program.state_names, state))
        if self.program.discrete is None:
            values.update(zip(self.program.input_names, action))
        values["action"] = action
        return values
