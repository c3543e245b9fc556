"""A batch's simulations stepped by MuJoCo's own batch API (``mujoco.batch.Batch``, MuJoCo 3.17 and later).

``mujoco.batch`` steps many simulations on its own C thread pool, bit-identical to a loop of
MjData (its documentation; ``tests/physics/test_mujoco_batch.py`` holds each env of a batch to one env
alone, resets and blow-ups included), and gives what a step computed as ``(N, size)`` arrays: a
batch step is one call, with no Python per env. It is *persistent* (one MjData per simulation,
each a whole MjData as a lane's would be) and runs each simulation on its lane's own MjModel
(``set_models``), so a reset that writes one env's model writes that env's alone.

The lanes' MjData no longer step; they hold each env's state where the lane needs it whole:
after a reset (the lane resets its MjData, then :meth:`MujocoBatch.load` gives the batch that
state) and when the lane steps, reads or is handed out alone (:meth:`MujocoBatch.sync` copies the
batch's MjData into it). A renderer poses each env from whichever of the two holds it
(:meth:`MujocoBatch.pose_sources`).

Where it does not fit, :func:`batch_module` says so and the batch steps the lanes' MjData itself
(:mod:`visualenv.physics.batch`):

* declared contacts: the batch's arrays do not hold MuJoCo's contact list (``data.contact``);
* dm_control's convention with mocap poses moved in ``dynamics.update``: dm_control's step
  finishes the last step (``mj_step2``) from kinematics computed before the new mocap pose was
  written, where the batch computes them from the new pose (qpos differs after three steps).
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, Sequence

import numpy as np

from visualenv.compat.mujoco import batch_api

#: MjData arrays a renderer poses the drawn model from (:func:`visualenv.physics.geom_poses.render_poses`)
POSE_ARRAYS = ("xpos", "xquat", "cam_xpos", "cam_xmat", "light_xpos", "light_xdir", "geom_xpos", "geom_xmat")


def batch_module(convention: str, contacts: bool, moved: bool) -> Any | None:
    """``mujoco.batch`` where it can step this batch to the bit (see the module's docstring), else None: the installed
    mujoco has none (before 3.17), the spec declares contacts, or it moves mocap bodies under dm_control's convention."""
    if contacts or (moved and convention == "dm_control"):
        return None
    return batch_api()


class MujocoBatch:
    """The lanes' simulations (`sims`, one per env) in one persistent ``mujoco.batch.Batch`` on `workers` threads."""

    def __init__(
        self,
        api: Any,
        sims: Sequence[Any],
        fields: Sequence[str],
        workers: int,
        moved: Sequence[str] = (),
        models_written: bool = False,
    ) -> None:
        first = sims[0]
        mujoco = self.mujoco = first.mujoco
        self.sims = list(sims)
        self.num_envs = n = len(self.sims)
        self.batch = api.Batch(first.model, n, nthread=workers, persistent=True)
        self.batch.set_models([sim.model for sim in self.sims])
        #: whether a reset may write the lanes' models: the batch is then given them again (mujoco.batch asks for it)
        self._models_written, self._models_changed = models_written, False
        self.frame_skip = first.frame_skip
        #: dm_control's step ends with mj_step1 (positions, velocities and what depends on them at the new state): stage VEL
        self._stage = int(
            mujoco.mjtStage.mjSTAGE_VEL if first.convention == "dm_control" else mujoco.mjtStage.mjSTAGE_NONE
        )
        # Gymnasium's step ends with mj_rnePostConstraint: a synced lane does too
        self._post = first.convention != "dm_control"
        #: the batch's (N, size) views of what each env's reads take (MjData fields: the state's, and what a step computed)
        self.outputs = {f: self.batch.bind(f).reshape(n, -1) for f in fields}
        self.ctrl = self.batch.bind("ctrl").reshape(n, -1)
        table = first.physics.names.values
        self._moved = [
            (
                self.batch.bind(array).reshape(n, -1),
                np.array([table[m][1] for m in moved if table[m][0] == array], int),
                np.array([k for k, m in enumerate(moved) if table[m][0] == array], int),
            )
            for array in sorted({table[m][0] for m in moved})
        ]
        # (N, warnings, (lastinfo, number)): each simulation's own counters, writable
        self.warnings = self.batch.warning
        self._signature = mujoco.mjtState.mjSTATE_INTEGRATION
        #: whether env i's lane holds its whole MjData (after a reset or a sync); else the batch's MjData i is ahead of it
        self.current = np.ones(n, dtype=bool)
        poses = {f: self.batch.bind(f) for f in POSE_ARRAYS}
        self._rows = [SimpleNamespace(**{f: array[i] for f, array in poses.items()}) for i in range(n)]
        self._sources: list[Any] | None = None

    def load(self, i: int) -> None:
        """Env i's state, as its lane holds it (after a reset), into the batch: MuJoCo's integration state and warning counters."""
        sim = self.sims[i]
        self.mujoco.mj_getState(sim.model, sim.data, self.batch.state[i], self._signature)
        self.warnings[i, :, 0] = sim.data.warning.lastinfo
        self.warnings[i, :, 1] = sim.data.warning.number
        self._models_changed |= self._models_written
        self._mark(i, True)

    def sync(self, i: int) -> None:
        """Env i's lane made whole: the batch's MjData of env i copied into it, if the batch stepped it since."""
        if not self.current[i]:
            sim = self.sims[i]
            self.batch.get_data(i, sim.data)
            if self._post:
                self.mujoco.mj_rnePostConstraint(sim.model, sim.data)
            self._mark(i, True)

    def step(self, envs: np.ndarray, ctrl: np.ndarray, moved: np.ndarray, fatal: Sequence[int]) -> list[int]:
        """`envs` (ascending) stepped frame_skip times with their rows of `ctrl` and of the mocap poses `moved`; the envs among
        them whose fatal MuJoCo warnings rose."""
        if not envs.size:
            return []
        if self._models_changed:
            self.batch.set_models([sim.model for sim in self.sims])
            self._models_changed = False
        rows = slice(None) if envs.size == self.num_envs else envs
        self.ctrl[rows] = ctrl[rows]
        for view, at, columns in self._moved:
            view[np.ix_(envs, at)] = moved[np.ix_(envs, columns)]
        before = self.warnings[:, fatal, 1].sum(axis=1)
        self.batch.step(
            None if envs.size == self.num_envs else envs.astype(np.int32), nstep=self.frame_skip, stage=self._stage
        )
        self._mark(envs, False)
        rose = self.warnings[:, fatal, 1].sum(axis=1) != before
        return [int(i) for i in envs[rose[envs]]]

    def pose_sources(self) -> list[Any]:
        """Per env, what a renderer poses it from: its lane's MjData where that holds it, else the batch's rows (live views);
        the same list until an env moves from one to the other."""
        if self._sources is None:
            self._sources = [
                sim.data if current else row for sim, current, row in zip(self.sims, self.current.tolist(), self._rows)
            ]
        return self._sources

    def _mark(self, envs: Any, current: bool) -> None:
        if self._sources is not None and (self.current[envs] != current).any():
            self._sources = None
        self.current[envs] = current


__all__ = ["MujocoBatch", "POSE_ARRAYS", "batch_module"]
