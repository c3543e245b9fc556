"""N envs' simulations stepped together, their named values read as numpy columns across envs.

A batch of a physics spec runs the program's vectorised step (:mod:`visualenv.compiler.batch_step`)
on columns: its reads of the model's names and its MuJoCo step are this module's. Env i steps on
its own MjModel (that of its lane, so env i of a batch is env i alone), ``frame_skip`` physics
steps as the spec's convention makes them, in one call for the batch:

* by MuJoCo's own batch API where the installed mujoco has it and it fits the spec
  (:mod:`visualenv.physics.batch_mujoco`): its C threads step the envs, and what they computed
  comes back as ``(N, size)`` arrays;
* else each lane's MjData, split over a thread pool where there are cores for it (MuJoCo releases
  the GIL while it steps), each env's arrays copied into ``(N, size)`` arrays after its step.

Either way a read is one numpy indexing per field for the whole batch, and a step's reads before
the MuJoCo step see the values after the last one (or after a reset, copied from the lane).

``mujoco.rollout`` is not used: it steps scratch MjData from state vectors and returns states, not
the stepped MjData (body poses, sensors after ``mj_rnePostConstraint``, contacts) nor the solver's
warm start, which the next step starts from: env i would no longer equal env i alone to the bit.
"""

from __future__ import annotations

import copy
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from visualenv.physics.model_fields import MODEL_PREFIX, SCALARS, array_view
from visualenv.physics.batch_mujoco import MujocoBatch, batch_module
from visualenv.physics.simulation import FATAL_WARNINGS, Simulation, touching

#: environment variable: threads that step a batch's simulations (default: see :func:`default_workers`)
THREADS_VARIABLE = "VISUALENV_PHYSICS_THREADS"
#: envs per thread below which a thread pool costs more than it saves
ENVS_PER_WORKER = 16


def default_workers(num_envs: int) -> int:
    """Threads for a batch: one per usable core, each with at least ENVS_PER_WORKER envs, or the variable's count."""
    given = os.environ.get(THREADS_VARIABLE, "").strip()
    if given:
        try:
            return max(1, int(given))
        except ValueError:
            raise ValueError(f"{THREADS_VARIABLE}={given!r}: expected a number of threads") from None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(cores, num_envs // ENVS_PER_WORKER))


class BatchSimulation:
    """The simulations of a batch's envs (one per env, in env order), stepped and read together."""

    def __init__(
        self,
        sims: Sequence[Simulation],
        reads: Mapping[str, Sequence[str]],
        controls: Sequence[str],
        workers: int | None = None,
        moved: Sequence[str] = (),
        models_written: bool = False,
    ) -> None:
        self.sims = list(sims)
        first = self.sims[0]
        self.num_envs = n = len(self.sims)
        self.frame_skip = first.frame_skip
        table = first.physics.names.values
        self.contacts = dict(first.contacts)
        used = {table[name][0] for names in reads.values() for name in names if name in table}
        self.fields = sorted(used | {"qpos", "qvel"})  # qpos and qvel always: a NaN in them is a blow-up
        self.values = {
            f: np.zeros((n, 1 if f in SCALARS else array_view(first.model, first.data, f).size)) for f in self.fields
        }
        self.touching = {c: np.zeros(n, dtype=bool) for names in reads.values() for c in names if c in self.contacts}
        self._copies = [self._copies_of(i) for i in range(n)]
        self._ctrl_at = np.array([table[c][1] for c in controls], dtype=int)
        self._ctrl = np.zeros((n, first.model.nu))
        #: the mocap poses dynamics.update sets (after the controls in advance()'s columns), written into each env before its step
        self._moved = np.zeros((n, len(moved)))
        self._movers = [sim.scatter(moved) for sim in self.sims] if moved else None
        warning = first.mujoco.mjtWarning
        self._fatal = [int(getattr(warning, w)) for w in FATAL_WARNINGS]
        #: the envs the next :meth:`advance` steps (a batch leaves out those it resets instead)
        self.active = np.arange(n)
        #: the envs whose last step blew up (MuJoCo's warning or a non-finite qpos/qvel)
        self.blown = np.zeros(n, dtype=bool)
        #: what the step in progress says may fault before its MuJoCo step (:meth:`watch`), and the MjData kept for those envs
        self._errors: Any = ()
        self._suspects: np.ndarray | None = None
        self.kept: dict[int, Any] = {}
        #: what each named read returned last, per env: a step replayed alone reads the same (:meth:`recorded`)
        self._last: dict[str, tuple[list[str], list[np.ndarray]]] = {}
        self._physics_step = first.physics_step  # the spec's convention's step (visualenv.physics.conventions)
        # copied by refresh(), not by the plain row copies
        self._extra = any(f in self.values for f in SCALARS) or bool(self.touching)
        #: per env, what its step touches: model, data, MuJoCo's warning counters, its ctrl, its row of controls, its copies
        self._lanes = [
            (sim.model, sim.data, sim.data.warning.number, sim.data.ctrl, self._ctrl[i], self._copies[i])
            for i, sim in enumerate(self.sims)
        ]
        self.workers = max(1, min(default_workers(n) if workers is None else workers, n))
        api = batch_module(first.convention, bool(self.touching), bool(moved))
        #: MuJoCo's own batch API stepping the envs (None: the lanes' MjData are stepped here, on a thread pool)
        self.engine = (
            None
            if api is None
            else MujocoBatch(
                api,
                self.sims,
                [f for f in self.fields if not f.startswith(MODEL_PREFIX)],
                self.workers,
                moved,
                models_written,
            )
        )
        self._pool = None
        if self.engine is None and self.workers > 1:
            self._pool = ThreadPoolExecutor(self.workers - 1, thread_name_prefix="visualenv-mujoco")
        for i in range(n):
            self.refresh(i)

    def _copies_of(self, i: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """(row of the batch array, the env's live MjData or MjModel array) for each field but the scalars."""
        sim = self.sims[i]
        return [(self.values[f][i], array_view(sim.model, sim.data, f)) for f in self.fields if f not in SCALARS]

    # -- state ---------------------------------------------------------------------------------------

    def refresh(self, i: int) -> None:
        """Env i's arrays copied into the batch's (after its reset, or a step it took alone)."""
        for row, live in self._copies[i]:
            row[:] = live
        data = self.sims[i].data
        for f in SCALARS:
            if f in self.values:
                self.values[f][i, 0] = getattr(data, f)
        for c, column in self.touching.items():
            column[i] = touching(data, self.contacts[c])
        if self.engine is not None:
            self.engine.load(i)

    def sync(self, i: int) -> None:
        """Env i's lane's MjData made whole before the lane steps, reads or is handed out (MuJoCo's batch steps its own)."""
        if self.engine is not None:
            self.engine.sync(i)

    def pose_sources(self) -> list[Any]:
        """Per env, what a renderer poses it from (MjData's pose arrays as attributes); the same list while nothing moved."""
        return [sim.data for sim in self.sims] if self.engine is None else self.engine.pose_sources()

    def close(self) -> None:
        """The pool's threads ended; MuJoCo's batch let go, every lane's MjData made whole first."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        if self.engine is not None:
            for i in range(self.num_envs):
                self.engine.sync(i)
            self.engine = None

    # -- the generated code's calls ------------------------------------------------------------------

    def reader(self, names: Sequence[str], key: str) -> Callable[[], tuple]:
        """read(): `names` as columns (one value per env), from the copies of the last step; remembered as read `key`."""
        table = self.values
        plan: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        values = self.sims[0].physics.names.values
        for f in sorted({values[n][0] for n in names if n in values}):
            at = [(j, values[n][1]) for j, n in enumerate(names) if n in values and values[n][0] == f]
            plan.append((table[f], np.array([j for j, _ in at], int), np.array([k for _, k in at], int)))
        touching = [(j, self.touching[n]) for j, n in enumerate(names) if n in self.touching]
        size, order = len(names), list(names)
        last = self._last

        def read() -> tuple:
            out: list[Any] = [None] * size
            for array, dst, src in plan:
                block = array[:, src]  # a copy: the step that follows refreshes the arrays
                for j, column in zip(dst.tolist(), block.T):
                    out[j] = column
            for j, column in touching:
                out[j] = column.copy()
            last[key] = (order, out)
            return tuple(out)

        return read

    def watch(self, errors: Any, suspects: np.ndarray | None) -> None:
        """Before a step: the record of the values it meets that Python raises on (float_errors', true once one was
        met), and the envs whose action is not finite.

        One env's step can fault before its MuJoCo step (a division by zero, a NaN action floored)
        and leave its MjData as it was, where the batch has stepped every env: if the step met an
        error before :meth:`advance`, every active env's MjData is kept (else the suspects'), for
        :meth:`put_back` (rare: no bundled spec meets one).
        """
        self._errors, self._suspects = errors, suspects

    def put_back(self, i: int) -> None:
        """Env i's MjData as it was before the last step (kept by :meth:`advance`), and the batch's copies of it."""
        data = self.kept.pop(i, None)
        if data is not None:
            sim = self.sims[i]
            sim.mujoco.mj_copyData(sim.data, sim.model, data)
            self.refresh(i)

    def advance(self, controls: Iterable[Any]) -> None:
        """Every active env's controls (columns, in the program's control order), then its frame_skip MuJoCo steps.

        Envs whose step blew up are marked in :attr:`blown` (their data is left as MuJoCo left
        it, as one env's is); the env replays its step alone to raise the located fault.
        """
        self.kept = {}
        if self._errors or self._suspects is not None:
            keep = self.active if self._errors else self.active[self._suspects[self.active]]  # type: ignore[index]
            for i in keep.tolist():
                self.sync(i)
                self.kept[i] = copy.copy(self.sims[i].data)
        n = self.num_envs
        ctrl = self._ctrl
        ctrl[:] = 0.0
        columns = [np.broadcast_to(np.asarray(c, dtype=np.float64), (n,)) for c in controls]
        count = self._ctrl_at.size
        if count:
            ctrl[:, self._ctrl_at] = np.column_stack(columns[:count])
        self.blown[:] = False
        active = self.active.tolist()
        # an env whose mocap pose is not finite is not stepped: alone, it raises before its step
        if self._movers is not None:
            self._moved[:] = np.column_stack(columns[count:])
            finite = np.isfinite(self._moved).all(axis=1)
            self.blown[[i for i in active if not finite[i]]] = True
            active = [i for i in active if finite[i]]
        if self.engine is not None:
            warned = self._step_engine(np.array(active, dtype=int))
        elif self._pool is None or len(active) < 2 * self.workers:
            warned = self._run(active)
        else:
            size = -(-len(active) // self.workers)
            chunks = [active[k : k + size] for k in range(0, len(active), size)]
            futures = [self._pool.submit(self._run, chunk) for chunk in chunks[1:]]
            warned = self._run(chunks[0])
            for future in futures:
                warned += future.result()
        if warned:
            self.blown[warned] = True
        finite = np.isfinite(self.values["qpos"]).all(axis=1) & np.isfinite(self.values["qvel"]).all(axis=1)
        self.blown[self.active] |= ~finite[self.active]

    def _step_engine(self, envs: np.ndarray) -> list[int]:
        """`envs` stepped by MuJoCo's batch, what they computed copied into the batch's arrays; the envs MuJoCo warned about."""
        engine = self.engine
        assert engine is not None
        warned = engine.step(envs, self._ctrl, self._moved, self._fatal)
        rows = slice(None) if envs.size == self.num_envs else envs
        for f, out in engine.outputs.items():
            self.values[f][rows] = out[rows]
        return warned

    def _run(self, envs: list[int]) -> list[int]:
        """Step `envs` one after another (a thread's share): controls, the steps, the copies; the envs MuJoCo warned about."""
        step, frame_skip = self._physics_step, self.frame_skip
        w0, w1, w2, w3 = self._fatal
        lanes, refresh, extra, movers = self._lanes, self.refresh, self._extra, self._movers
        warned: list[int] = []
        for i in envs:
            model, data, counters, ctrl, ctrl_row, copies = lanes[i]
            c = counters.tolist()
            before = c[w0] + c[w1] + c[w2] + c[w3]
            ctrl[:] = ctrl_row
            if movers is not None:
                movers[i](self._moved[i])
            step(model, data, frame_skip)
            c = counters.tolist()
            if c[w0] + c[w1] + c[w2] + c[w3] != before:
                warned.append(i)
            if extra:
                refresh(i)
            else:
                for row, live in copies:
                    row[:] = live
        return warned

    def recorded(self, i: int, keys: Iterable[str]) -> dict[str, tuple]:
        """Env i's values of the reads `keys` as the last batch step made them, as its own reads return them (floats, contacts as bools)."""
        out: dict[str, tuple] = {}
        for key in keys:
            if key in self._last:
                names, columns = self._last[key]
                out[key] = tuple(bool(c[i]) if n in self.touching else float(c[i]) for n, c in zip(names, columns))
        return out


__all__ = ["BatchSimulation", "THREADS_VARIABLE", "default_workers"]
