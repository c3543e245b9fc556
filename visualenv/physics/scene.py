"""What a renderer needs to draw an MJCF model: its visible geoms, lights and cameras, as plain data.

Made once from the compiled MjModel (and its pose after ``mj_forward`` at qpos0),
so a renderer builds its objects without knowing MuJoCo: each body is a frame
whose world pose arrives as arrays every step (``xpos``, ``xquat``); each geom a
shape fixed in its body's frame. Geoms in groups MuJoCo's viewer hides by
default (3 and up) are left out; a height field (or any type a renderer cannot
draw) is a :class:`~visualenv.physics.model.PhysicsError` naming the geom.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from visualenv.physics.model import PhysicsError, PhysicsModel, mujoco_module

#: MuJoCo's geom types (mjtGeom) a renderer draws
GEOM_KINDS = {0: "plane", 2: "sphere", 3: "capsule", 4: "ellipsoid", 5: "cylinder", 6: "box", 7: "mesh"}
#: groups 0, 1 and 2 are visible in MuJoCo's viewer by default
VISIBLE_GROUPS = 3
#: a plane of size 0 is infinite in MuJoCo; drawn this many metres across
INFINITE_PLANE = 200.0
_DEFAULT_RGBA = (0.5, 0.5, 0.5, 1.0)


@dataclass(frozen=True)
class GeomShape:
    name: str  # the geom's name, or geom<i>
    kind: str  # a value of GEOM_KINDS
    body: int
    size: tuple[float, float, float]  # MuJoCo's size (half extents, radius and half length...); a plane's: its half extents
    pos: tuple[float, float, float]  # in the body's frame
    quat: tuple[float, float, float, float]  # w, x, y, z, in the body's frame
    rgba: tuple[float, float, float, float]
    vertices: np.ndarray | None = None  # mesh geoms: (n, 3) in the geom's frame
    faces: np.ndarray | None = None  # mesh geoms: (m, 3) vertex indices
    texture: np.ndarray | None = None  # planes: the material's 2-D texture, (h, w, 4) floats in 0..1, bottom row first (Blender's order)
    texrepeat: tuple[float, float] = (1.0, 1.0)  # repetitions across the plane, or per metre when texuniform
    texuniform: bool = False


@dataclass(frozen=True)
class LightInfo:
    name: str
    directional: bool
    pos: tuple[float, float, float]  # world, at qpos0
    direction: tuple[float, float, float]
    diffuse: tuple[float, float, float]
    cutoff: float  # spot cone half angle (degrees)


@dataclass(frozen=True)
class CameraInfo:
    name: str
    fovy: float  # vertical field of view (degrees)
    moves: bool = False  # it tracks a body, or hangs on one that moves
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)  # its place at qpos0 (where a camera that does not move stays)
    xmat: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)  # its orientation there, row-major (MuJoCo's cam_xmat)


@dataclass(frozen=True)
class PhysicsScene:
    """The drawable part of a model; bodies by index, so poses are rows of MjData's xpos and xquat."""

    body_names: tuple[str, ...]
    body_pos: np.ndarray  # (nbody, 3) world positions at qpos0 (bodies that never move stay there)
    body_quat: np.ndarray  # (nbody, 4)
    moving: np.ndarray  # indices of the bodies that can move (jointed, or below a jointed body, or mocap)
    geoms: tuple[GeomShape, ...]
    lights: tuple[LightInfo, ...]
    cameras: tuple[CameraInfo, ...]


def physics_scene(physics: PhysicsModel) -> PhysicsScene:
    """The scene of `physics`: refuses a visible height field (not drawn yet), names every geom and camera."""
    mujoco = mujoco_module()
    model = physics.model
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    idents = physics.names.ident
    geoms = []
    for g in range(model.ngeom):
        if int(model.geom_group[g]) >= VISIBLE_GROUPS or float(model.geom_rgba[g][3]) == 0.0:
            continue
        gtype = int(model.geom_type[g])
        if gtype not in GEOM_KINDS:
            kind = {1: "a height field (hfield)", 8: "an SDF"}.get(gtype, f"of type {gtype}")
            raise PhysicsError(f"geom '{idents['geom'][g]}' is {kind}, which visualenv cannot draw yet: move it to group 3 "
                               "(hidden) or replace it with a mesh or boxes")
        geoms.append(_geom(model, g, GEOM_KINDS[gtype], idents["geom"][g]))
    lights = tuple(
        LightInfo(idents["light"][i], bool(_light_directional(model, i)), tuple(map(float, data.light_xpos[i])),  # type: ignore[arg-type]
                  tuple(map(float, data.light_xdir[i])), tuple(map(float, model.light_diffuse[i])), float(model.light_cutoff[i]))  # type: ignore[arg-type]
        for i in range(model.nlight))
    moving = np.flatnonzero((model.body_weldid != 0) | (model.body_mocapid >= 0))
    cameras = tuple(CameraInfo(idents["camera"][i], float(model.cam_fovy[i]), int(model.cam_mode[i]) != 0 or int(model.cam_bodyid[i]) in set(moving.tolist()),
                               tuple(map(float, data.cam_xpos[i])), tuple(map(float, data.cam_xmat[i])))  # type: ignore[arg-type]
                    for i in range(model.ncam))
    return PhysicsScene(tuple(idents["body"]), data.xpos.copy(), data.xquat.copy(), moving, tuple(geoms), lights, cameras)


def _light_directional(model: Any, i: int) -> bool:
    if hasattr(model, "light_type"):
        return int(model.light_type[i]) == 1  # mjLIGHT_DIRECTIONAL
    return bool(model.light_directional[i])


def _geom(model: Any, g: int, kind: str, name: str) -> GeomShape:
    rgba = tuple(float(v) for v in model.geom_rgba[g])
    mat = int(model.geom_matid[g])
    if mat >= 0 and np.allclose(rgba, _DEFAULT_RGBA):  # MuJoCo: a material's colour wins over the default geom colour
        rgba = tuple(float(v) for v in model.mat_rgba[mat])
    size = tuple(float(v) for v in model.geom_size[g])
    if kind == "plane":
        size = tuple(v if v > 0 else INFINITE_PLANE / 2 for v in size[:2]) + (size[2],)
    vertices = faces = None
    if kind == "mesh":
        mesh = int(model.geom_dataid[g])
        v0, nv = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
        f0, nf = int(model.mesh_faceadr[mesh]), int(model.mesh_facenum[mesh])
        vertices = np.array(model.mesh_vert[v0:v0 + nv], dtype=np.float64)
        faces = np.array(model.mesh_face[f0:f0 + nf], dtype=np.int64)
    texture, repeat, uniform = _plane_texture(model, mat) if kind == "plane" and mat >= 0 else (None, (1.0, 1.0), False)
    return GeomShape(name, kind, int(model.geom_bodyid[g]), size, tuple(map(float, model.geom_pos[g])),  # type: ignore[arg-type]
                     tuple(map(float, model.geom_quat[g])), rgba, vertices, faces, texture, repeat, uniform)  # type: ignore[arg-type]


def _plane_texture(model: Any, mat: int) -> tuple[np.ndarray | None, tuple[float, float], bool]:
    """A plane material's 2-D texture as MuJoCo compiled it (builtin checker, gradient, flat, or an image: all are pixels by then)."""
    texids = np.atleast_1d(model.mat_texid[mat])
    rgb_role = 1 if texids.size > 1 else 0  # MuJoCo 3: one texture per role, mjTEXROLE_RGB = 1
    tex = int(texids[rgb_role])
    if tex < 0 or int(model.tex_type[tex]) != 0:  # none, or a cube/skybox texture (not drawn on planes)
        return None, (1.0, 1.0), False
    w, h = int(model.tex_width[tex]), int(model.tex_height[tex])
    channels = int(model.tex_nchannel[tex]) if hasattr(model, "tex_nchannel") else 3
    adr = int(model.tex_adr[tex])
    pixels = np.asarray(model.tex_data[adr:adr + w * h * channels], dtype=np.float32).reshape(h, w, channels) / 255.0
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :min(channels, 3)] = pixels[..., :3]
    if channels == 1:
        rgba[..., 1] = rgba[..., 2] = pixels[..., 0]
    repeat = tuple(float(v) for v in model.mat_texrepeat[mat])
    return rgba[::-1].copy(), (repeat[0], repeat[1]), bool(model.mat_texuniform[mat])
