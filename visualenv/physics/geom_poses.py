"""Geoms a reset moves, drawn as bodies of their own: the scene's part, and the poses a renderer takes each render.

A renderer draws each geom fixed in its body's frame and poses bodies from MjData's ``xpos`` and
``xquat`` (:mod:`visualenv.physics.scene`). A reset that writes a geom's model position
(``model_geom_pos_<g>_x``: reacher's target, drawn anew each episode) moves the geom within its
body, which a body's pose does not say. So each such geom is drawn on a body of its own, appended
after the model's bodies (index ``nbody + k``, named ``geom:<g>``), posed from the geom's own
world pose (``geom_xpos``, and ``geom_xmat`` as a quaternion): a single env and a batch (whose envs
each draw their own target) pose it as any moving body, from the arrays :func:`render_poses` gives.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Sequence

import numpy as np

from visualenv.physics.model import PhysicsModel, mujoco_module
from visualenv.physics.scene import PhysicsScene


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
