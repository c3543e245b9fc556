"""The names that read a model's own numbers: geoms' world positions, joints' anchors, the contact count, and MjModel
fields a reset may write.

DeepMind Control's tasks read and write the model in ``initialize_episode`` and their rewards
(reacher moves its target geom and reads the geoms' radii, finger sets its hinge's damping, the
joint randomiser draws in each joint's range, ball_in_cup counts contacts). These names say that
in a spec:

* ``geom_<g>_x/_y/_z``: a geom's world position (MjData's ``geom_xpos``), as ``body_`` and ``site_`` names are;
* ``joint_<j>_x/_y/_z``: a joint's anchor in the world (MjData's ``xanchor``), which finger turn's reset reads;
* ``ncon``: the number of contacts MuJoCo found (MjData's ``ncon``): ``ncon == 0`` is nothing touching;
* ``model_<field>_<element>`` and ``model_<field>_<element>_<column>``: the element's row of MjModel's
  ``<field>`` (:data:`MODEL_FIELDS`), as dm_control's ``physics.named.model.<field>[element, column]``
  reads it: ``model_geom_pos_target_x``, ``model_geom_size_finger_0``, ``model_jnt_range_wrist_lo``,
  ``model_dof_damping_hinge`` (a degree of freedom is named as its ``qvel_`` name without ``qvel_``).
  A reset may write the fields in :data:`WRITABLE` (``physics.reset.values``); each env has its own
  MjModel, so a write changes that env alone, and lasts until the next write (as dm_control's does).

A name's array is MjData's attribute, or ``model.<field>`` for MjModel's; :func:`live_array` gives
the flat live view a reader indexes (none for the scalars, read as attributes each time).
"""

from __future__ import annotations

from typing import Any, Callable, Collection, Mapping, Sequence

import numpy as np

#: MjModel fields as names: field -> (the kind of element a row belongs to, the names of its columns; () for one value)
MODEL_FIELDS: dict[str, tuple[str, tuple[str, ...]]] = {
    "geom_pos": ("geom", ("x", "y", "z")),
    "geom_size": ("geom", ("0", "1", "2")),
    "site_pos": ("site", ("x", "y", "z")),
    "site_size": ("site", ("0", "1", "2")),
    "jnt_range": ("joint", ("lo", "hi")),
    "dof_damping": ("dof", ()),
}
#: the fields a reset may write: geoms' and sites' positions and sizes (drawn where and as large as written) and a degree
#: of freedom's damping (physics alone); joint ranges are read only
WRITABLE = ("geom_pos", "geom_size", "site_pos", "site_size", "dof_damping")
#: a name's array is MjModel's field when it starts so
MODEL_PREFIX = "model."
#: MjData's scalars a name reads (as attributes, each time: no view holds them)
SCALARS = ("time", "ncon")


def model_array(field: str) -> str:
    """The array key of MjModel's `field` in the name tables."""
    return MODEL_PREFIX + field


def is_writable(array: str) -> bool:
    """Whether a name of this array may be written by a reset (a model field of :data:`WRITABLE`)."""
    return array.startswith(MODEL_PREFIX) and array[len(MODEL_PREFIX) :] in WRITABLE


def written_geoms(names: Collection[str], table: Mapping[str, tuple[str, int]], field: str = "geom_pos") -> list[int]:
    """The elements (ids, ascending) whose row of `field` (a field of three columns) `names` write: by default the geoms
    whose model position a renderer moves after a reset."""
    return sorted({table[n][1] // 3 for n in names if table.get(n, ("", 0))[0] == model_array(field)})


def live_array(model: Any, data: Any, array: str) -> np.ndarray | None:
    """The flat live view of a name's array: MjModel's for a model field, MjData's otherwise; None for a scalar."""
    return None if array in SCALARS else array_view(model, data, array)


def array_view(model: Any, data: Any, array: str) -> np.ndarray:
    """The flat live view of an array that is not a scalar (:data:`SCALARS`): MjModel's field or MjData's array."""
    if array.startswith(MODEL_PREFIX):
        return np.asarray(getattr(model, array[len(MODEL_PREFIX) :])).reshape(-1)
    return np.atleast_1d(getattr(data, array)).reshape(-1)


def model_values(
    model: Any, ident: Mapping[str, list[str]], owners: Mapping[str, list[str]], qvel: Mapping[str, int]
) -> list[tuple[str, tuple[str, int], str]]:
    """Every name of this module for `model`, as (name, (array, flat index), the element an error names it by).

    `ident` and `owners` hold each element's identifier and description by kind (``geom``, ``site``,
    ``joint``); `qvel` is the ``qvel_`` names' dof indices, which name the degrees of freedom.
    """
    out: list[tuple[str, tuple[str, int], str]] = []
    for g, name in enumerate(ident["geom"]):
        for i, p in enumerate("xyz"):
            out.append((f"geom_{name}_{p}", ("geom_xpos", 3 * g + i), owners["geom"][g]))
    for j, name in enumerate(ident["joint"]):
        for i, p in enumerate("xyz"):
            out.append((f"joint_{name}_{p}", ("xanchor", 3 * j + i), owners["joint"][j]))
    out.append(("ncon", ("ncon", 0), "the contact count"))
    dofs = {index: name[len("qvel_") :] for name, index in qvel.items()}
    for field, (kind, columns) in MODEL_FIELDS.items():
        width = max(len(columns), 1)
        if kind == "dof":
            rows = [(d, dofs[d], owners["joint"][int(model.dof_jntid[d])]) for d in sorted(dofs)]
        else:
            rows = [(k, name, owners[kind][k]) for k, name in enumerate(ident[kind])]
        for k, name, owner in rows:
            for c, column in enumerate(columns or ("",)):
                out.append(
                    (
                        f"model_{field}_{name}" + (f"_{column}" if column else ""),
                        (model_array(field), width * k + c),
                        owner,
                    )
                )
    return out


def model_writer(
    model: Any, table: Mapping[str, tuple[str, int]], names: Sequence[str]
) -> Callable[[np.ndarray], None]:
    """write(values): the model fields among `names` (values in `names`' order) written into `model`; nothing for the others."""
    plan = []
    for array in sorted({table[n][0] for n in names if table[n][0].startswith(MODEL_PREFIX)}):
        at = [(i, table[n][1]) for i, n in enumerate(names) if table[n][0] == array]
        view = array_view(model, None, array)
        plan.append((view, np.array([q for _, q in at], int), np.array([p for p, _ in at], int)))

    def write(values: np.ndarray) -> None:
        for view, dst, src in plan:
            view[dst] = values[src]

    return write


def written_fields(model: Any) -> dict[str, np.ndarray]:
    """Copies of `model`'s fields a reset may write: what a pickled env carries besides MuJoCo's state."""
    return {field: np.array(getattr(model, field)) for field in WRITABLE}


def restore_fields(model: Any, fields: Mapping[str, np.ndarray]) -> None:
    """Put fields saved by :func:`written_fields` back into `model` (an env's own MjModel)."""
    for field, values in fields.items():
        getattr(model, field)[...] = values
