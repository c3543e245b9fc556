"""What one render call is given: :class:`Frames`, the state of N envs (N >= 1) to draw.

A renderer built for N envs (:attr:`~visualenv.render.base.Renderer.n`) renders
every env's observation, or its view, from one ``Frames``: one row of binding
values per env and, where the env has them, each env's physics poses and its
distraction. A single env is the case N = 1: ``Frames((values,))``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from visualenv.render.distractions import Distraction

#: one env's binding values, a flat tuple in ``RenderPlan.bindings`` order
BindingValues = tuple[float, ...]

#: one env's MuJoCo poses: xpos, xquat, cam_xpos, cam_xmat, light_xpos, light_xdir (the lights' None where the
#: model has none), as ``PhysicsPlan.poses`` gives them: live views of the env's MjData, so Frames copy nothing
Poses = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]


@dataclass(frozen=True)
class Frames:
    """The state of N envs for one render: row i is env i's.

    ``values`` is the binding table: a sequence of N tuples of binding values, or an
    ``(N, k)`` float array (a batch computes its table as one array, ``BatchedVectorEnv.binding_table``).
    ``poses`` holds N entries of :data:`Poses` for a physics spec (None: the spec has no
    model, or its poses have not moved). ``distractions`` holds N draws (None: keep those
    drawn before; an env without distractions passes None). ``envs``, ascending env
    indices, asks for those envs' observations only (an autoreset re-renders the envs it reset).
    """

    values: Sequence[BindingValues] | np.ndarray
    poses: Sequence[Poses] | None = None
    distractions: Sequence[Distraction] | None = None
    envs: Sequence[int] | None = None

    @property
    def n(self) -> int:
        """How many envs these frames hold."""
        return len(self.values)

    def copy(self) -> Frames:
        """These frames with their own copy of each array (poses are live views of MjData: a copy keeps this state)."""
        values = self.values.copy() if isinstance(self.values, np.ndarray) else tuple(map(tuple, self.values))
        poses = None if self.poses is None else [tuple(None if a is None else a.copy() for a in p) for p in self.poses]
        return Frames(values, poses, self.distractions, self.envs)  # type: ignore[arg-type]
