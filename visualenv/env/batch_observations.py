"""What a batch shows: :class:`BatchObservations`, the observation half of
:class:`~visualenv.env.batch.BatchedVectorEnv`.

Apart from the step (which moves every env's state, in :mod:`visualenv.env.batch`), this turns the envs' state into
what they show: the frames the renderer draws (the binding table, a physics spec's MuJoCo poses, each env's
distraction), each env's observation (its tile of one render through its sensor, or its state vector), and the
``render_mode="human"`` grid. Where the vectorised functions cannot give an env's values, its lane gives them, as
env i alone would (the same values, or its located fault).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any, Callable

import numpy as np

from visualenv.compiler.batch_functions import float_errors
from visualenv.compiler.program import BatchFunctions, Program
from visualenv.compiler.render_plan import distractions_plan
from visualenv.env.human import HumanDisplay, grid, open_human_display
from visualenv.env.visual_env import VisualEnv
from visualenv.errors import StepError
from visualenv.render.base import RenderPlan, Renderer, RendererOptions, load_backend
from visualenv.render.distractions import Distraction, EpisodeDistractions
from visualenv.render.frames import Frames
from visualenv.render.profile import Profile
from visualenv.render.sensor import SensorModel
from visualenv.spec.models import Distractions


class BatchObservations:
    """The observations, bindings and views of a batch: a mixin of BatchedVectorEnv, which sets what it reads."""

    num_envs: int
    program: Program
    uses_camera: bool
    distractions: Distractions | None
    profile: Profile | None
    _lanes: list[VisualEnv]
    _lane_at: Callable[[int], VisualEnv]
    _state: np.ndarray
    _steps: np.ndarray
    _batch: BatchFunctions
    _physics: Any
    _pose_arrays: list[tuple] | None
    _pose_sources: list[Any] | None
    _sensors: dict[str, SensorModel]
    _distractions: list[EpisodeDistractions]
    _renderer: Any
    _renderer_options: RendererOptions
    _backend: str
    _display: HumanDisplay | None

    @property
    def renderer(self) -> Renderer:
        """The batch renderer, built on first use."""
        if self._renderer is None:
            self._renderer = load_backend(self._backend)(
                self._render_plan(), self._renderer_options, num_envs=self.num_envs
            )
        return self._renderer

    def _render_plan(self) -> RenderPlan:
        """The program's render plan with the options' overrides and the distractions the envs will draw."""
        return replace(
            self.program.render_plan().with_options(self._renderer_options),
            distractions=distractions_plan(self.distractions),
        )

    @property
    def segmentation_ids(self) -> dict[str, int]:
        """Id of each label (or unlabelled object name) in segmentation observations, the same in every env; builds the renderer."""
        if not self.uses_camera:
            return {}
        return dict(getattr(self.renderer, "segmentation_ids", {}))

    def _frames(self, envs: np.ndarray | None = None) -> Frames:
        """Every env's state to draw: the binding table, a physics spec's MuJoCo poses, each env's distraction."""
        distractions = [d.current or Distraction() for d in self._distractions] if self._distractions else None
        poses = None
        if self.program.physics is not None:
            plan = self.program.physics
            sources = self._physics.pose_sources() if self._physics is not None else [lane.data for lane in self._lanes]
            # live views, made once (moved geoms: copies)
            if self._pose_arrays is None or plan.posed_geoms or sources is not self._pose_sources:
                self._pose_arrays = [plan.poses(source) for source in sources]
                self._pose_sources = sources
            poses = self._pose_arrays
        start = time.perf_counter()
        table = self.binding_table()
        if self.profile is not None:
            self.profile.add("bind", time.perf_counter() - start)
        return Frames(table, poses, distractions, None if envs is None else [int(i) for i in envs])

    def _observe(self, envs: np.ndarray | None = None) -> Any:
        """Every env's observation, or those of `envs` (ascending indices) only."""
        if not self.uses_camera and self.program.physics is not None:  # each env's MuJoCo data (float64, Gymnasium's)
            return self._physics_observations(envs)
        if not self.uses_camera:
            observed = self._state[self.program.observed].T.astype(np.float32)
            return observed if envs is None else observed[envs]
        obs = self.renderer.render(self._frames(envs))
        if self._sensors:
            obs = self._through_sensors(obs, envs)
        return obs

    def _physics_observations(self, envs: np.ndarray | None) -> np.ndarray:
        """A physics spec's state-only observations: the batch's columns, or each lane's own where they are not finite (or not vectorised)."""
        n = self.num_envs
        rows = range(n) if envs is None else [int(i) for i in envs]
        observe = self._batch.observe
        if observe is None:
            return np.stack([self._lane_at(i).physics_observation() for i in rows])
        with float_errors() as errors:
            columns = observe(tuple(self._state), self._steps)
        table = np.ascontiguousarray(
            np.array([np.broadcast_to(np.asarray(c, dtype=np.float64), (n,)) for c in columns])
            .reshape(len(columns), n)
            .T
        )
        for i in range(n) if errors else np.flatnonzero(~np.isfinite(table).all(axis=1)):
            table[i] = self._lane_at(int(i)).physics_observation()  # the same values, or the lane's own error
        return table if envs is None else table[list(rows)]

    def _through_sensors(self, obs: Any, envs: np.ndarray | None) -> Any:
        """Each env's frames through the sensor models, drawn from its lane's generator (as env i alone would draw them)."""
        rows = range(self.num_envs) if envs is None else [int(i) for i in envs]
        if isinstance(obs, dict):
            out = {key: value.copy() for key, value in obs.items()}
            for row, i in enumerate(rows):
                noisy = self._lanes[i].apply_sensors({key: value[row] for key, value in obs.items()}, self._sensors)
                for key in out:
                    out[key][row] = noisy[key]
            return out
        out = obs.copy()
        for row, i in enumerate(rows):
            out[row] = self._lanes[i].apply_sensors(obs[row], self._sensors)
        return out

    def binding_values(self) -> list[tuple]:
        """Every env's actor binding values (program.bindings order)."""
        return list(map(tuple, self.binding_table().tolist()))

    def binding_table(self) -> np.ndarray:
        """Every env's actor binding values as one array, ``(N, values)``: what the renderer takes (no tuple per env)."""
        bind = self._batch.bind
        n = self.num_envs
        if bind is None:
            return np.array([self._lane_bindings(i) for i in range(n)], dtype=np.float64).reshape(n, -1)
        with float_errors() as errors:
            values = bind(tuple(self._state), self._steps)
        table = (
            np.array([np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)) for v in values])
            .reshape(len(values), n)
            .T.copy()
        )
        for i in range(n) if errors else np.flatnonzero(~np.isfinite(table).all(axis=1)):
            table[i] = self._lane_bindings(int(i))  # the same values, or the located fault
        return table

    def _lane_bindings(self, i: int) -> tuple:
        """Env i's binding values computed by its lane, as one env computes them; a fault names env i."""
        try:
            return self._lane_at(i).binding_values()
        except StepError as err:
            raise err.in_env(i) from None

    def _show(self, obs: Any) -> None:
        """render_mode="human": the observations as a grid (one per camera), and env 0's step, on the display."""
        if self._display is None:
            self._display = open_human_display()
        pictures = {key: grid(frames) for key, frames in obs.items()} if isinstance(obs, dict) else grid(obs)
        values = {
            "envs": self.num_envs,
            "steps": int(self._steps[0]),
            "state": {n: float(v) for n, v in zip(self.program.state_names, self._state[:, 0])},
        }
        self._display.show(self.program.spec.id, pictures, values)
