"""One MjData stepped for one env: reset, controls, frame_skip steps, and readers of named values.

Stepping follows Gymnasium's MujocoEnv exactly (``ctrl[:] = action``,
``mj_step(nstep=frame_skip)``, then ``mj_rnePostConstraint``; a reset is
``mj_resetData``, the new qpos and qvel, then ``mj_forward``), or dm_control's
Physics (:mod:`visualenv.physics.conventions`), so a spec that writes the
library's reward and reset draws reproduces its env to the last bit.
Named values are gathered by readers made once per list of names: one numpy
indexing per array, never a Python lookup per name on the hot path.
"""

from __future__ import annotations

import copy
import math
from contextlib import contextmanager
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from visualenv.physics.conventions import forward_function, reset_data, step_function
from visualenv.physics.model import SETTABLE, PhysicsModel, mujoco_module
from visualenv.physics.model_fields import live_array, model_writer


class PhysicsFault(ValueError):
    """The simulation blew up (a non-finite state, or MuJoCo's own warning); the env reports it located, with the step."""


#: MuJoCo warnings that mean the simulation is no longer trustworthy (MuJoCo resets the state on a bad qacc and goes on)
FATAL_WARNINGS = ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC", "mjWARN_BADCTRL")


def touching(data: Any, pair: tuple[int, int]) -> bool:
    """Whether the geoms `pair` touch in `data`'s contact list (in either order): a declared contact's value."""
    ncon = data.ncon
    if not ncon:
        return False
    g1, g2 = data.contact.geom1[:ncon], data.contact.geom2[:ncon]
    a, b = pair
    return bool((((g1 == a) & (g2 == b)) | ((g1 == b) & (g2 == a))).any())


def integration_state(data: Any) -> np.ndarray:
    """MuJoCo's whole integration state of `data` (``mjSTATE_INTEGRATION``: time, qpos, qvel, act, warm start,
    controls...): what the next ``mj_step`` starts from, so that two equal states step alike to the bit."""
    mujoco = mujoco_module()
    signature = mujoco.mjtState.mjSTATE_INTEGRATION
    state = np.empty(mujoco.mj_stateSize(data.model, signature))
    mujoco.mj_getState(data.model, data, state, signature)
    return state


class Simulation:
    """An env's MjModel (its own copy, so randomising one env's model leaves the others alone, without the textures
    only the renderer reads: :attr:`PhysicsModel.dynamics`) and MjData."""

    def __init__(
        self,
        physics: PhysicsModel,
        frame_skip: int,
        contacts: dict[str, tuple[int, int]] | None = None,
        convention: str = "gymnasium",
    ) -> None:
        self.mujoco = mujoco_module()
        #: whose MuJoCo calls the steps and resets make (:mod:`visualenv.physics.conventions`)
        self.convention = convention
        self.physics_step = step_function(convention, self.mujoco)
        self.physics = physics
        self.model = copy.copy(physics.dynamics)
        self.data = self.mujoco.MjData(self.model)
        self.frame_skip = frame_skip
        self.contacts = dict(contacts or {})
        warnings = self.mujoco.mjtWarning
        self._fatal = np.array([int(getattr(warnings, w)) for w in FATAL_WARNINGS])
        self._warnings = self.data.warning.number  # a live view of MuJoCo's warning counters
        #: while a batch replays this env's step (:meth:`replaying`): the values its reads had before the step, by read
        self._replay: Mapping[str, tuple] | None = None
        self._replay_blown = False
        #: whether the last replayed step reached its MuJoCo step (False: it faulted before, and one env's data was not stepped)
        self.replay_stepped = False

    # -- reset and step -----------------------------------------------------------------------------

    def reset(self, keyframe: int | None = None) -> None:
        """``mj_resetData``, or the keyframe's state (then dm_control's forward); the spec's reset values are written after (:meth:`set_state`)."""
        reset_data(self.convention, self.mujoco, self.model, self.data, keyframe)

    def writer(self, names: Sequence[str], forward: bool = True) -> Callable[[Sequence[float]], None]:
        """set_state(values): write qpos/qvel, mocap and model fields `names` (in order), then ``mj_forward`` (as Gymnasium's
        set_state; dm_control's after_reset), unless not `forward` (a reset that goes on with a redraw or settling steps)."""
        write = self.scatter(names)
        write_model = model_writer(self.model, self.physics.names.values, names)
        data, model, forward_pass = (
            self.data,
            self.model,
            forward_function(self.convention, self.mujoco) if forward else None,
        )

        def set_state(values: Sequence[float]) -> None:
            given = np.asarray(values, dtype=np.float64)
            if not np.isfinite(given).all():
                bad = [f"{n}={v!r}" for n, v in zip(names, given) if not math.isfinite(v)]
                raise PhysicsFault(f"a reset value is not finite: {', '.join(bad)}")
            write_model(given)
            write(given)
            if forward_pass is not None:
                forward_pass(model, data)

        return set_state

    def scatter(self, names: Sequence[str]) -> Callable[[np.ndarray], None]:
        """write(values): `names`' values (settable: joint values, mocap poses) into the MjData arrays, one indexing per array."""
        table = self.physics.names.values
        plan = []
        for array in SETTABLE:
            at = [(i, table[n][1]) for i, n in enumerate(names) if table[n][0] == array]
            if at:
                view = getattr(self.data, array).reshape(-1)  # a view: MjData's arrays are contiguous
                plan.append((view, np.array([q for _, q in at], int), np.array([p for p, _ in at], int)))

        def write(values: np.ndarray) -> None:
            for view, dst, src in plan:
                view[dst] = values[src]

        return write

    def stepper(self, controls: Sequence[str], moved: Sequence[str] = ()) -> Callable[[Sequence[float]], None]:
        """advance(values): actuator controls for `controls` (``ctrl_<actuator>`` names; others 0) and, after them in
        `values`, the mocap poses `moved` (``mocap_<body>_...``, set before the step as ctrl is), then frame_skip steps."""
        table = self.physics.names.values
        where = np.array([table[n][1] for n in controls], int)
        ctrl = np.zeros(self.model.nu)
        count = len(controls)
        move = self.scatter(moved) if moved else None
        data, model, step, n = self.data, self.model, self.physics_step, self.frame_skip
        warnings, fatal = self._warnings, self._fatal.tolist()
        qpos, qvel = data.qpos, data.qvel

        def advance(values: Sequence[float]) -> None:
            if move is not None:
                given = np.asarray(values, dtype=np.float64)
                if not np.isfinite(given[count:]).all():
                    bad = [f"{m}={v!r}" for m, v in zip(moved, given[count:]) if not math.isfinite(v)]
                    raise PhysicsFault(f"a mocap pose set in dynamics.update is not finite: {', '.join(bad)}")
                if self._replay is None:
                    move(given[count:])
                values = given[:count].tolist()
            if self._replay is not None:  # a batch stepped this env already: only its fault is left to raise
                self.replay_stepped = True
                if self._replay_blown:
                    raise PhysicsFault(self.blown_up())
                return
            ctrl[where] = values
            data.ctrl[:] = ctrl
            counts = warnings.tolist()  # eight numbers: cheaper as a list than as numpy reductions
            before = sum(counts[i] for i in fatal)
            step(model, data, n)
            counts = warnings.tolist()
            # MuJoCo resets the state on a bad qacc and warns; a NaN from the last substep shows in qpos or qvel
            if sum(counts[i] for i in fatal) != before or not math.isfinite(qpos.sum() + qvel.sum()):
                raise PhysicsFault(self.blown_up())

        return advance

    def settle(self, nstep: int, time: float | None) -> None:
        """`nstep` physics steps in one call of the convention's step, with the controls as they are (a reset's settling steps,
        as dm_control's ``physics.step(nstep)`` in a task's ``initialize_episode``), then the time set to `time` (if given)."""
        data, fatal = self.data, self._fatal.tolist()
        counts = self._warnings.tolist()
        before = sum(counts[i] for i in fatal)
        self.physics_step(self.model, data, nstep)
        counts = self._warnings.tolist()
        if sum(counts[i] for i in fatal) != before or not math.isfinite(data.qpos.sum() + data.qvel.sum()):
            raise PhysicsFault(self.blown_up())
        if time is not None:
            data.time = time

    def blown_up(self) -> str:
        """What went wrong, in MuJoCo's words and numbers: the warnings raised and the non-finite values."""
        parts = []
        for w in FATAL_WARNINGS:
            index = int(getattr(self.mujoco.mjtWarning, w))
            info = self.data.warning[index]
            if info.number:
                dof = self.physics.qvel_names()
                where = (
                    f" at {dof[info.lastinfo]}"
                    if w in ("mjWARN_BADQACC", "mjWARN_BADQVEL") and 0 <= info.lastinfo < len(dof)
                    else ""
                )
                parts.append(f"MuJoCo warning {w[7:]}{where}")
        for array in ("qpos", "qvel", "qacc"):
            values = getattr(self.data, array)
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                names = self.physics.qpos_names() if array == "qpos" else self.physics.qvel_names()
                parts.append(f"{array} not finite: " + ", ".join(f"{names[i]}={values[i]!r}" for i in bad[:6]))
        state = ", ".join(f"{n}={v:.6g}" for n, v in zip(self.physics.qpos_names(), self.data.qpos[:8]))
        return (
            f"the MuJoCo simulation blew up at sim_time={self.data.time:.6g} ({'; '.join(parts) or 'unstable'}); "
            f"qpos: {state}; lower the timestep or the controls, or check the model"
        )

    # -- reading named values -----------------------------------------------------------------------

    def reader(self, names: Sequence[str], key: str = "") -> Callable[[], tuple]:
        """read(): the current values of `names` (value names and declared contacts), as a tuple of floats (contacts: bools).

        `key` names the read (the generated code's ``before``, ``after``...): while a batch replays
        the step (:meth:`replaying`), a read it recorded returns the recorded values.
        """
        table = self.physics.names.values
        plan: list[tuple[str, np.ndarray, np.ndarray]] = []
        for array in {table[n][0] for n in names if n in table}:
            at = [(i, table[n][1]) for i, n in enumerate(names) if n in table and table[n][0] == array]
            plan.append((array, np.array([p for p, _ in at], int), np.array([q for _, q in at], int)))
        touches = [(i, self.contacts[n]) for i, n in enumerate(names) if n in self.contacts]
        data, size = self.data, len(names)
        views = {a: live_array(self.model, data, a) for a, _, _ in plan}  # None: a scalar (time, ncon), read each time
        out = np.zeros(size)

        def read() -> tuple:
            if self._replay is not None and key in self._replay:
                return self._replay[key]
            for array, dst, src in plan:
                view = views[array]
                out[dst] = getattr(data, array) if view is None else view[src]
            values = out.tolist()
            for i, pair in touches:
                values[i] = touching(data, pair)
            return tuple(values)

        return read

    @contextmanager
    def replaying(self, reads: Mapping[str, tuple], blown: bool) -> Iterator[None]:
        """This env's generated step run again after a batch has stepped its MjData (:mod:`visualenv.physics.batch`).

        The reads named in `reads` return the values the batch read before the step, the
        MuJoCo step is not taken again (or raises the blow-up, when `blown`), and reads after it
        see the stepped data: the step's result, or its located fault, is exactly this env's alone.
        """
        self._replay, self._replay_blown, self.replay_stepped = reads, blown, False
        try:
            yield
        finally:
            self._replay, self._replay_blown = None, False
