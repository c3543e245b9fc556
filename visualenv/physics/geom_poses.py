"""Geoms a reset moves, drawn as bodies of their own: the scene's part, and the poses a renderer takes each render.

A renderer draws each geom fixed in its body's frame and poses bodies from MjData's ``xpos`` and
``xquat`` (:mod:`visualenv.physics.scene`). A reset that writes a geom's model position
(``model_geom_pos_<g>_x``: reacher's target, drawn anew each episode) moves the geom within its
body, which a body's pose does not say. So each such geom is drawn on a body of its own, appended
after the model's bodies (index ``nbody + k``, named ``geom:<g>``), posed from the geom's own
world pose (``geom_xpos``, and ``geom_xmat`` as a quaternion): a single env and a batch (whose envs
each draw their own target) pose it as any moving body, from the arrays :func:`render_poses` gives.

A reset that writes a drawn geom's or site's size (``model_geom_size_<g>_0``: reacher hard's target), or a site's
position (``model_site_pos_<s>_x``: finger turn's target), is drawn by a binding of the object the renderer made of it
(:func:`drawn_writes`): its scale, the size written over the size its mesh was built at, and a site's location in its
body's frame, the position written; the compiler binds them (:mod:`visualenv.compiler.bindings`), so a single env and
each env of a batch draw their own.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Collection, Sequence

import numpy as np

from visualenv.physics.model import PhysicsModel, mujoco_module
from visualenv.physics.model_fields import model_array, written_geoms
from visualenv.physics.scene import GeomShape, PhysicsScene

#: the size columns that scale each axis of a shape drawn at its size (a sphere's radius; an ellipsoid's and a box's
#: half sizes; a cylinder's radius and half length): a capsule (its caps would stretch), a plane or a mesh is not rescaled
SCALED_BY = {"sphere": (0, 0, 0), "ellipsoid": (0, 1, 2), "box": (0, 1, 2), "cylinder": (0, 0, 1)}


@dataclass(frozen=True)
class DrawnWrite:
    """A binding that draws what a reset writes: `prop` (scale, location) of `object`, each value a model field's
    name over a divisor (a scale's: the size the mesh was built at)."""

    object: str
    prop: str
    values: tuple[tuple[str, float], ...]


def with_posed_geoms(scene: PhysicsScene, physics: PhysicsModel, geoms: Sequence[int]) -> PhysicsScene:
    """`scene` with each drawn geom of `geoms` (MuJoCo ids) on a body of its own, posed from the geom's world pose."""
    mujoco = mujoco_module()
    names = physics.names.ident["geom"]
    drawn = {shape.name: i for i, shape in enumerate(scene.geoms)}
    moved = [g for g in geoms if names[g] in drawn]
    if not moved:
        return scene
    model = physics.model
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    first = len(scene.body_names)
    shapes = list(scene.geoms)
    for k, g in enumerate(moved):
        i = drawn[names[g]]
        shapes[i] = replace(shapes[i], body=first + k, pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0))
    xpos, xquat = geom_world_poses(data, moved)
    return replace(
        scene,
        body_names=(*scene.body_names, *(f"geom:{names[g]}" for g in moved)),
        body_pos=np.concatenate([scene.body_pos, xpos]),
        body_quat=np.concatenate([scene.body_quat, xquat]),
        moving=np.concatenate([scene.moving, np.arange(first, first + len(moved))]),
        geoms=tuple(shapes),
    )


def geom_world_poses(data: Any, geoms: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """The world positions (k x 3) and orientations w, x, y, z (k x 4) of `geoms` in `data` (after a forward)."""
    mujoco = mujoco_module()
    rows = np.asarray(geoms, dtype=int)
    quats = np.empty((len(rows), 4))
    for k, g in enumerate(rows.tolist()):
        mujoco.mju_mat2Quat(quats[k], data.geom_xmat[g])
    return data.geom_xpos[rows], quats


def render_poses(data: Any, geoms: Sequence[int]) -> tuple:
    """(xpos, xquat, cam_xpos, cam_xmat, light_xpos, light_xdir) of `data`, the moved `geoms`' poses appended to the bodies'
    (:func:`with_posed_geoms`); without any, MjData's live arrays themselves (nothing copied)."""
    if not geoms:
        return data.xpos, data.xquat, data.cam_xpos, data.cam_xmat, data.light_xpos, data.light_xdir
    xpos, xquat = geom_world_poses(data, geoms)
    return (
        np.concatenate([data.xpos, xpos]),
        np.concatenate([data.xquat, xquat]),
        data.cam_xpos,
        data.cam_xmat,
        data.light_xpos,
        data.light_xdir,
    )


def drawn_writes(
    scene: PhysicsScene, physics: PhysicsModel, written: Collection[str], own: Collection[str] = ()
) -> tuple[list[DrawnWrite], list[tuple[str, str]]]:
    """The bindings that draw the model fields `written` (a reset's names) of the drawn geoms and sites, and the names
    whose write cannot be drawn, with why (the size of a drawn capsule, plane or mesh). `own`: the bodies a spec's
    object stands for, whose geoms and sites are not drawn."""
    table, ident = physics.names.values, physics.names.ident
    rows = {kind: {name: i for i, name in enumerate(ident[kind])} for kind in ("geom", "site")}
    sized = {kind: set(written_geoms(written, table, f"{kind}_size")) for kind in ("geom", "site")}
    moved = set(written_geoms(written, table, "site_pos"))
    out: list[DrawnWrite] = []
    problems: list[tuple[str, str]] = []
    drawn = [(s, "geom", s.name) for s in scene.geoms] + [(s, "site", s.name[len("site:") :]) for s in scene.sites]
    for shape, kind, element in drawn:
        row = rows[kind][element]
        if scene.body_names[shape.body] in own:
            continue
        if row in sized[kind] and shape.kind not in SCALED_BY:
            field = model_array(f"{kind}_size")
            name = next(n for n in written if table[n][0] == field and table[n][1] // 3 == row)
            problems.append((name, _unscalable(kind, element, shape)))
        elif row in sized[kind]:
            values = tuple((f"model_{kind}_size_{element}_{c}", shape.size[c]) for c in SCALED_BY[shape.kind])
            out.append(DrawnWrite(shape.name, "scale", values))
        if kind == "site" and row in moved:
            out.append(DrawnWrite(shape.name, "location", tuple((f"model_site_pos_{element}_{p}", 1.0) for p in "xyz")))
    return out, problems


def _unscalable(kind: str, element: str, shape: GeomShape) -> str:
    return (
        f"the {kind} '{element}' is drawn as a {shape.kind}, which cannot be drawn at another size: a reset may write the "
        f"size of a drawn {', '.join(SCALED_BY)} (drawn scaled), or of a {kind} in a hidden group (3 and up)"
    )
