"""The rules of an episode, written once for one env and for a batch of N: :class:`EpisodeRules`.

What a step's result means for the episode is decided here and nowhere else:
which outcome ends it (terminated or truncated) and what ``info["outcome"]``
says, truncation after ``max_steps``, success (an outcome or a milestone marked
``success``), the milestones fired, the keys of ``info``, which results are
faults (NaN, an infinity, a state the float32 observation cannot hold) and how
an episode a fault ended looks. :class:`~visualenv.env.visual_env.VisualEnv`
asks the scalar methods (Python numbers: its step is a hot path);
:class:`~visualenv.env.batch.BatchedVectorEnv` asks their array twins, which
take one value per env, from the same tables. A fault is described (located,
with the values it read) by one env, the batch's lane, so its message is one
env's; a batch only names the env: :meth:`StepError.in_env
<visualenv.errors.StepError.in_env>`.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from visualenv.compiler.program import Program
from visualenv.env.faults import OBSERVATION_LIMIT, FaultDiagnosis

#: ``info["outcome"]`` of an episode that reached its step limit, and of one a fault ended (``on_fault: terminate``)
OUT_OF_STEPS, FAULT = "max_steps", "error"
#: the keys of every step's ``info`` (``error`` is added to those of a step a fault ended)
INFO_KEYS = ("state", "steps", "outcome", "milestones", "is_success")


def step_limit(program: Program, max_episode_steps: Any) -> int:
    """The step after which episodes are truncated: the spec's ``max_steps``, or Gymnasium's ``max_episode_steps`` when given."""
    if max_episode_steps is None:
        return program.spec.max_steps
    if (
        isinstance(max_episode_steps, bool)
        or not isinstance(max_episode_steps, (int, np.integer))
        or max_episode_steps < 1
    ):
        raise ValueError(f"max_episode_steps must be an integer of at least 1, got {max_episode_steps!r}")
    return int(max_episode_steps)


class EpisodeRules:
    """Endings, truncation, outcomes, success, milestones, info and faults of one program's episodes.

    ``observes_state``: the observation is the float32 state vector (state-only, no
    physics), so a finite state past float32's range is a fault, as NaN is.
    """

    def __init__(self, program: Program, max_steps: int, *, observes_state: bool) -> None:
        self.program = program
        #: episodes are truncated after this many steps
        self.max_steps = max_steps
        #: ``on_fault: raise``: a fault raises its StepError; else (``terminate``) it ends the episode
        self.raises = program.spec.on_fault == "raise"
        self.faults = FaultDiagnosis(program)
        rules = program.outcomes
        milestones = [r for r in rules if r.end == "none"]
        #: milestone i (in spec order) is bit i of ``fired``
        self.milestones = [r.name for r in milestones]
        self.success_bits = sum(1 << i for i, r in enumerate(milestones) if r.success)
        # one row per outcome index the generated step returns, and a last one for -1 (no outcome held)
        table = [(r.end == "terminate", r.end == "truncate", r.name, r.success) for r in rules] + [
            (False, False, None, False)
        ]
        self._endings = [row[:3] for row in table]
        self._successful = [row[3] for row in table]
        self._terminates = np.array([row[0] for row in table], dtype=bool)
        self._truncates = np.array([row[1] for row in table], dtype=bool)
        self._names = np.array([row[2] for row in table], dtype=object)
        self._successes = np.array(self._successful, dtype=bool)
        self._observed = program.observed if observes_state else []
        # the largest magnitude each state variable may reach: float32's where it is observed as float32, else float64's
        # (so a single test, abs(x) <= limit, refuses NaN, infinities and values past float32 at once)
        limits = np.full(len(program.state_names), np.finfo(np.float64).max)
        limits[self._observed] = OBSERVATION_LIMIT
        self._limits = limits[:, None]
        self._tightest = float(limits.min()) if limits.size else math.inf

    # -- one env: Python numbers ----------------------------------------------------------------------

    def ending(self, outcome: int, steps: int) -> tuple[bool, bool, str | None]:
        """(terminated, truncated, info["outcome"]) after a step: the ending outcome that held, else the step limit, else none."""
        ending = self._endings[outcome]
        if steps >= self.max_steps and not (ending[0] or ending[1]):
            return False, True, OUT_OF_STEPS
        return ending

    def succeeded(self, success: bool, outcome: int, newly_fired: int) -> bool:
        """Whether the episode is a success after a step: it was, the ending outcome is one, or a milestone marked success fired."""
        return success or self._successful[outcome] or bool(newly_fired & self.success_bits)

    def milestone_names(self, fired: int) -> list[str]:
        """The fired milestones' names, in spec order."""
        return [m for i, m in enumerate(self.milestones) if fired >> i & 1] if fired else []

    def info(
        self, state: dict[str, float], steps: int, outcome: str | None, fired: int, success: bool
    ) -> dict[str, Any]:
        """One env's ``info`` (:data:`INFO_KEYS`)."""
        return {
            "state": state,
            "steps": steps,
            "outcome": outcome,
            "milestones": self.milestone_names(fired),
            "is_success": success,
        }

    def fault_info(self, state: dict[str, float], steps: int, fired: int, success: bool, error: str) -> dict[str, Any]:
        """The ``info`` of a step a fault ended (``on_fault: terminate``): outcome ``"error"``, the message in ``error``.

        Such a step has reward 0, is terminated and not truncated, and leaves the state as it was.
        """
        info = self.info(state, steps, FAULT, fired, success)
        info["error"] = error
        return info

    def check(self, state: tuple, reward: float, values: Callable[[], dict[str, Any]], steps: int) -> None:
        """A step's result as the episode may take it, else its located StepError: NaN or an infinity anywhere,
        or a state the float32 observation cannot hold; ``values()`` gives what the step read, for the message."""
        total = sum(state) + reward
        if total - total != 0:  # NaN or infinity somewhere
            self.faults.check_step(state, reward, values(), steps)
        for i in self._observed:
            if not -OBSERVATION_LIMIT <= state[i] <= OBSERVATION_LIMIT:
                self.faults.check_observable(state, "dynamics.update.{}", values(), steps)

    def check_reset(self, state: tuple, steps: int) -> None:
        """A state drawn at reset as an episode may start from, else its located StepError (not finite, past float32)."""
        self.faults.check_reset(state, steps)
        if self._observed:
            self.faults.check_observable(state, "state.{}.init", dict(zip(self.program.state_names, state)), steps)

    # -- N envs: one array element per env, from the same tables ---------------------------------------

    def endings(self, outcome: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`ending` of each env: (terminated, truncated, info["outcome"]) arrays."""
        terminated, truncated = self._terminates[outcome], self._truncates[outcome]
        out_of_steps = (steps >= self.max_steps) & ~(terminated | truncated)
        return terminated, truncated | out_of_steps, np.where(out_of_steps, OUT_OF_STEPS, self._names[outcome])

    def successes(self, success: np.ndarray, outcome: np.ndarray, newly_fired: np.ndarray) -> np.ndarray:
        """:meth:`succeeded` of each env."""
        return success | self._successes[outcome] | ((newly_fired & self.success_bits) != 0)

    def unfit(self, state: np.ndarray, reward: np.ndarray) -> np.ndarray:
        """The envs whose result (state as ``(variables, envs)``, reward) :meth:`check` refuses: their lanes step them, and fault."""
        bad = ~np.isfinite(reward)
        # NaN, an infinity or a large value somewhere: whose?
        if state.size and not np.abs(state).max() <= self._tightest:
            bad |= ~(np.abs(state) <= self._limits).all(axis=0)
        return bad

    def milestone_lists(self, fired: np.ndarray) -> np.ndarray:
        """:meth:`milestone_names` of each env: one list per distinct set, shared by the envs that have it."""
        distinct, which = np.unique(fired, return_inverse=True)
        lists = np.empty(len(distinct), dtype=object)
        for j, bits in enumerate(distinct.tolist()):
            lists[j] = self.milestone_names(bits)
        return lists[which]

    def batch_info(
        self,
        state: np.ndarray,
        steps: np.ndarray,
        outcome: np.ndarray,
        fired: np.ndarray,
        success: np.ndarray,
        errors: np.ndarray,
        mask: np.ndarray,
    ) -> dict[str, Any]:
        """N envs' :meth:`info` in Gymnasium's vector layout: each key with its ``_key`` mask; ``state`` a dict of arrays
        (each variable with its ``_name`` mask, as Sync/AsyncVectorEnv nest a dict); ``error`` where a fault ended an env."""
        nested: dict[str, Any] = {}
        for j, name in enumerate(self.program.state_names):
            nested[name], nested[f"_{name}"] = state[j].copy(), mask.copy()
        values = (nested, steps.copy(), outcome.copy(), self.milestone_lists(fired), success.copy())
        info: dict[str, Any] = {}
        for key, value in zip(INFO_KEYS, values):
            info[key], info[f"_{key}"] = value, mask.copy()
        erred = errors != None  # noqa: E711 - element-wise
        if erred.any():
            info["error"], info["_error"] = errors.copy(), erred & mask
        return info
