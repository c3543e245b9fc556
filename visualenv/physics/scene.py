"""What a renderer needs to draw an MJCF model: its visible geoms, lights and cameras, as plain data.

Made once from the compiled MjModel (and its pose after ``mj_forward`` at qpos0),
so a renderer builds its objects without knowing MuJoCo: each body is a frame
whose world pose arrives as arrays every step (``xpos``, ``xquat``); each geom a
shape fixed in its body's frame, and so is each site (named ``site:<name>``).
Geoms and sites in groups MuJoCo's viewer hides by default (3 and up) are left
out; a height field (or any type a renderer cannot draw) is a
:class:`~visualenv.physics.model.PhysicsError` naming the geom. A
geom's 2-D or cube texture comes as pixels with the numbers MuJoCo's renderer
maps it by (:mod:`visualenv.physics.texcoords`); the model's skybox comes as the
equirectangular image a renderer shows behind the model.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from visualenv.compat.mujoco import light_directional, texture_channels
from visualenv.physics.model import PhysicsError, PhysicsModel, mujoco_module
from visualenv.physics.tendons import TendonShape, catenary_length
from visualenv.physics.texcoords import cube_to_equirect

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
    # MuJoCo's size (half extents, radius and half length...); a plane's: its half extents
    size: tuple[float, float, float]
    pos: tuple[float, float, float]  # in the body's frame
    quat: tuple[float, float, float, float]  # w, x, y, z, in the body's frame
    rgba: tuple[float, float, float, float]
    vertices: np.ndarray | None = None  # mesh geoms: (n, 3) in the geom's frame
    faces: np.ndarray | None = None  # mesh geoms: (m, 3) vertex indices
    # the material's texture, (h, w, 4) floats in 0..1, bottom row first (Blender's order)
    texture: np.ndarray | None = None
    texture_type: str = "2d"  # "2d", or "cube": six square faces stacked (h = 6 w), or one face for all six (h = w)
    texture_id: int = -1  # the MuJoCo texture's index (geoms that share one share its image)
    # MuJoCo's texgen scale (texcoords.py): 2d (x, y, -), cube (x, y, z)
    texscale: tuple[float, float, float] = (
        1.0,
        1.0,
        1.0,
    )
    unit: tuple[float, float, float] = (1.0, 1.0, 1.0)  # divides the geom's vertices into MuJoCo's object coordinates
    texcoords: np.ndarray | None = None  # mesh geoms with their own UVs: (m, 3, 2) Blender UVs per face corner
    #: added to a finite plane's vertices before its 2-D texture's mapping: MuJoCo 3.17's renderer lays the texture from
    #: the plane's (-x, +y) corner, not its centre (checked against mujoco.Renderer: tests/physics/test_texcoords.py)
    texorigin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: its material's emission (times its colour), specular and shininess, as MuJoCo's renderer lights it (no material: 0, 0.5, 0.5)
    emission: float = 0.0
    specular: float = 0.5
    shininess: float = 0.5
    material: str = ""  # its MuJoCo material's name ("" without one): a floor's is 'grid' (distractions fade it)


@dataclass(frozen=True)
class LightInfo:
    name: str
    directional: bool
    pos: tuple[float, float, float]  # world, at qpos0
    direction: tuple[float, float, float]
    diffuse: tuple[float, float, float]
    cutoff: float  # spot cone half angle (degrees)
    ambient: tuple[float, float, float] = (0.0, 0.0, 0.0)
    castshadow: bool = True
    exponent: float = 10.0  # a spot's intensity falls as cos(angle from its axis) ** exponent
    # a spot's intensity over (a0 + a1 d + a2 d^2), d its distance
    attenuation: tuple[float, float, float] = (
        1.0,
        0.0,
        0.0,
    )


@dataclass(frozen=True)
class Headlight:
    """MuJoCo's headlight (``visual/headlight``): a directional light along the camera's view that casts no shadow."""

    ambient: tuple[float, float, float] = (0.1, 0.1, 0.1)
    diffuse: tuple[float, float, float] = (0.4, 0.4, 0.4)
    specular: tuple[float, float, float] = (0.5, 0.5, 0.5)
    active: bool = True


@dataclass(frozen=True)
class CameraInfo:
    name: str
    fovy: float  # vertical field of view (degrees)
    moves: bool = False  # it tracks a body, or hangs on one that moves
    # world, at qpos0 (cam_xpos): where a camera that never moves stays
    pos: tuple[float, float, float] = (
        0.0,
        0.0,
        0.0,
    )
    # w, x, y, z of cam_xmat at qpos0 (looking down its -z, y up)
    quat: tuple[float, float, float, float] = (
        1.0,
        0.0,
        0.0,
        0.0,
    )
    #: its orientation changes (it hangs on a moving body, or aims at one); a track or trackcom camera keeps its own
    turns: bool = False


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
    #: the model's skybox as an equirectangular image (h, w, 4), bottom row first, z up (texcoords.cube_to_equirect):
    #: what MuJoCo draws behind the model and lights nothing with; None without a skybox texture
    sky: np.ndarray | None = None
    #: the visible sites, drawn as MuJoCo's viewer draws them (:func:`visible_sites`), each named ``site:<name>``
    sites: tuple[GeomShape, ...] = ()
    headlight: Headlight = Headlight()
    #: the visible spatial tendons through sites (:func:`visible_tendons`)
    tendons: tuple[TendonShape, ...] = ()
    #: how the renderer lights and colours the model (physics.look): "mujoco" as MuJoCo's OpenGL renderer, "physical" by Blender's lights
    look: str = "mujoco"


def physics_scene(physics: PhysicsModel, draw_sites: bool = True, look: str = "mujoco") -> PhysicsScene:
    """The scene of `physics`: refuses a visible height field (not drawn yet), names every geom and camera; its visible
    sites unless `draw_sites` is false; `look` is physics.look."""
    mujoco = mujoco_module()
    model = physics.model
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    idents = physics.names.ident
    geoms = []
    textures: dict[int, np.ndarray] = {}  # by MuJoCo texture index: geoms that share a texture share its pixels
    for g in range(model.ngeom):
        if int(model.geom_group[g]) >= VISIBLE_GROUPS or float(model.geom_rgba[g][3]) == 0.0:
            continue
        gtype = int(model.geom_type[g])
        if gtype not in GEOM_KINDS:
            kind = {1: "a height field (hfield)", 8: "an SDF"}.get(gtype, f"of type {gtype}")
            raise PhysicsError(
                f"geom '{idents['geom'][g]}' is {kind}, which visualenv cannot draw yet: move it to group 3 "
                "(hidden) or replace it with a mesh or boxes"
            )
        geoms.append(_geom(model, g, GEOM_KINDS[gtype], idents["geom"][g], textures))
    lights = tuple(
        LightInfo(
            idents["light"][i],
            light_directional(model, i),
            _floats(data.light_xpos[i]),  # type: ignore[arg-type]
            _floats(data.light_xdir[i]),  # type: ignore[arg-type]
            _floats(model.light_diffuse[i]),  # type: ignore[arg-type]
            float(model.light_cutoff[i]),
            _floats(model.light_ambient[i]),  # type: ignore[arg-type]
            bool(model.light_castshadow[i]),
            float(model.light_exponent[i]),
            _floats(model.light_attenuation[i]),  # type: ignore[arg-type]
        )
        for i in range(model.nlight)
    )
    head = model.vis.headlight
    headlight = Headlight(_floats(head.ambient), _floats(head.diffuse), _floats(head.specular), bool(head.active))  # type: ignore[arg-type]
    moving = np.flatnonzero((model.body_weldid != 0) | (model.body_mocapid >= 0))
    cameras = tuple(_camera(model, data, i, idents["camera"][i], set(moving.tolist())) for i in range(model.ncam))
    skyboxes = [t for t in range(model.ntex) if int(model.tex_type[t]) == 2]  # mjTEXTURE_SKYBOX
    sky = cube_to_equirect(_pixels(model, skyboxes[0])) if skyboxes else None
    sites = visible_sites(physics) if draw_sites else ()
    return PhysicsScene(
        tuple(idents["body"]),
        data.xpos.copy(),
        data.xquat.copy(),
        moving,
        tuple(geoms),
        lights,
        cameras,
        sky,
        sites,
        headlight,
        visible_tendons(physics),
        look,
    )


#: MuJoCo's camera modes (mjtCamLight) that keep a camera's orientation in the world: track, trackcom
STEADY_MODES = (1, 2)


def _camera(model: Any, data: Any, i: int, name: str, moving: set[int]) -> CameraInfo:
    """Camera i: its field of view, pose at qpos0, and whether it moves (a mode other than fixed, or a moving body) and turns."""
    mode, on_moving = int(model.cam_mode[i]), int(model.cam_bodyid[i]) in moving
    moves = mode != 0 or on_moving
    turns = moves and mode not in STEADY_MODES  # fixed on a moving body, or aimed at a body (targetbody, targetbodycom)
    return CameraInfo(
        name,
        float(model.cam_fovy[i]),
        moves,
        tuple(map(float, data.cam_xpos[i])),  # type: ignore[arg-type]
        _quat(mujoco_module(), data.cam_xmat[i]),  # type: ignore[arg-type]
        turns,
    )


def _floats(values: Any) -> tuple[float, ...]:
    return tuple(float(v) for v in values)


#: MuJoCo's wrap type (mjtWrap) of a path point that is a site
WRAP_SITE = 3


def visible_tendons(physics: PhysicsModel) -> tuple[TendonShape, ...]:
    """The tendons MuJoCo's viewer draws by default (groups 0 to 2, not transparent, of a width), whose path runs
    through sites alone: a tendon that wraps around a geom, or a fixed (joint) tendon, is not drawn yet."""
    model, mujoco = physics.model, mujoco_module()
    out = []
    for i in range(model.ntendon):
        start, count = int(model.tendon_adr[i]), int(model.tendon_num[i])
        rgba = tuple(float(v) for v in model.tendon_rgba[i])
        mat = int(model.tendon_matid[i])
        if mat >= 0 and np.allclose(rgba, _DEFAULT_RGBA):
            rgba = tuple(float(v) for v in model.mat_rgba[mat])
        if (
            int(model.tendon_group[i]) >= VISIBLE_GROUPS
            or rgba[3] == 0.0
            or float(model.tendon_width[i]) <= 0.0
            or count < 2
            or any(int(model.wrap_type[w]) != WRAP_SITE for w in range(start, start + count))
        ):
            continue
        sites = [int(model.wrap_objid[w]) for w in range(start, start + count)]
        emission, specular, shininess = _shading(model, mat)
        out.append(
            TendonShape(
                f"tendon:{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_TENDON, i) or f'tendon{i}'}",
                float(model.tendon_width[i]),
                rgba,  # type: ignore[arg-type]
                tuple((int(model.site_bodyid[s]), _floats(model.site_pos[s])) for s in sites),  # type: ignore[misc]
                catenary_length(model, i),
                _floats(model.opt.gravity),  # type: ignore[arg-type]
                min(int(model.vis.quality.numslices) + 1, 100),
                emission,
                specular,
                shininess,
            )
        )
    return tuple(out)


def visible_sites(physics: PhysicsModel) -> tuple[GeomShape, ...]:
    """The sites MuJoCo's viewer draws by default: groups 0 to 2 (``mjvOption.sitegroup``), not fully transparent; each a
    shape fixed in its body's frame, of its type, size and rgba (a material's colour where the rgba is MuJoCo's default)."""
    model = physics.model
    out = []
    for i, ident in enumerate(physics.names.ident["site"]):
        kind = GEOM_KINDS.get(int(model.site_type[i]))
        rgba = tuple(float(v) for v in model.site_rgba[i])
        if (
            int(model.site_group[i]) >= VISIBLE_GROUPS
            or rgba[3] == 0.0
            or kind not in ("sphere", "capsule", "ellipsoid", "cylinder", "box")
        ):
            continue
        mat = int(model.site_matid[i])
        if mat >= 0 and np.allclose(rgba, _DEFAULT_RGBA):
            rgba = tuple(float(v) for v in model.mat_rgba[mat])
        emission, specular, shininess = _shading(model, mat)
        out.append(
            GeomShape(
                f"site:{ident}",
                kind,
                int(model.site_bodyid[i]),
                tuple(float(v) for v in model.site_size[i]),  # type: ignore[arg-type]
                tuple(map(float, model.site_pos[i])),  # type: ignore[arg-type]
                tuple(map(float, model.site_quat[i])),  # type: ignore[arg-type]
                rgba,  # type: ignore[arg-type]
                emission=emission,
                specular=specular,
                shininess=shininess,
            )
        )
    return tuple(out)


def _quat(mujoco: Any, mat: np.ndarray) -> tuple[float, ...]:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.asarray(mat, dtype=np.float64).reshape(9))
    return tuple(float(v) for v in quat)


def _geom(model: Any, g: int, kind: str, name: str, textures: dict[int, np.ndarray]) -> GeomShape:
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
        vertices = np.array(model.mesh_vert[v0 : v0 + nv], dtype=np.float64)
        faces = np.array(model.mesh_face[f0 : f0 + nf], dtype=np.int64)
    emission, specular, shininess = _shading(model, mat)
    material = (mujoco_module().mj_id2name(model, mujoco_module().mjtObj.mjOBJ_MATERIAL, mat) or "") if mat >= 0 else ""
    shape = GeomShape(
        name,
        kind,
        int(model.geom_bodyid[g]),
        size,  # type: ignore[arg-type]
        tuple(map(float, model.geom_pos[g])),  # type: ignore[arg-type]
        tuple(map(float, model.geom_quat[g])),  # type: ignore[arg-type]
        rgba,  # type: ignore[arg-type]
        vertices,
        faces,
        emission=emission,
        specular=specular,
        shininess=shininess,
        material=material,
    )
    tex = _texture_id(model, mat)
    if tex < 0:
        return shape
    if tex not in textures:
        textures[tex] = _pixels(model, tex)
    return replace(
        shape,
        texture=textures[tex],
        texture_type="cube" if int(model.tex_type[tex]) == 1 else "2d",
        texture_id=tex,
        **_texgen(model, g, kind, mat, tex),
    )


def _shading(model: Any, mat: int) -> tuple[float, float, float]:
    """A material's emission, specular and shininess, or MuJoCo's (mjv_updateScene's) for an element without one."""
    if mat < 0:
        return 0.0, 0.5, 0.5
    return float(model.mat_emission[mat]), float(model.mat_specular[mat]), float(model.mat_shininess[mat])


def _texture_id(model: Any, mat: int) -> int:
    """The material's colour texture, if MuJoCo draws it on geoms: a 2-D or cube texture (a skybox is the world's)."""
    if mat < 0:
        return -1
    texids = np.atleast_1d(model.mat_texid[mat])
    rgb_role = 1 if texids.size > 1 else 0  # MuJoCo 3: one texture per role, mjTEXROLE_RGB = 1
    tex = int(texids[rgb_role])
    return tex if tex >= 0 and int(model.tex_type[tex]) in (0, 1) else -1


def _texgen(model: Any, g: int, kind: str, mat: int, tex: int) -> dict[str, Any]:
    """MuJoCo's texture coordinate generation for geom `g` (``settexture`` in render_gl3.c), as GeomShape fields.

    Primitives are MuJoCo's unit shapes scaled by their size (their object
    coordinates are the vertices over ``unit``); planes and meshes are drawn at
    their size (``unit`` 1), so a 2-D texture's repeat is divided by it.
    """
    raw = tuple(float(v) for v in model.geom_size[g])
    size = {"sphere": (raw[0],) * 3, "capsule": (raw[0], raw[0], raw[1]), "cylinder": (raw[0], raw[0], raw[1])}.get(
        kind, raw
    )
    drawn_at_size = kind in ("plane", "mesh")
    uniform = bool(model.mat_texuniform[mat])
    fields: dict[str, Any] = {"unit": (1.0, 1.0, 1.0) if drawn_at_size else size}
    if int(model.tex_type[tex]) == 1:  # cube: the object coordinates, times the size when uniform
        fields["texscale"] = size if uniform else (1.0, 1.0, 1.0)
    else:
        scale = [float(v) for v in model.mat_texrepeat[mat]]
        for k in (0, 1):
            if drawn_at_size and size[k] > 0:
                scale[k] /= max(size[k], 1e-15)
            if uniform and size[k] > 0:
                scale[k] *= size[k]
        fields["texscale"] = (scale[0], scale[1], 0.0)
        if kind == "plane":
            fields["texorigin"] = (raw[0], -raw[1], 0.0)  # 0 along an infinite dimension
    if kind == "mesh":
        fields["texcoords"] = _mesh_texcoords(model, int(model.geom_dataid[g]))
    return fields


def _mesh_texcoords(model: Any, mesh: int) -> np.ndarray | None:
    """A mesh's own texture coordinates per face corner, as Blender UVs; None when its file had none."""
    adr = int(model.mesh_texcoordadr[mesh])
    if adr < 0:
        return None
    f0, nf = int(model.mesh_faceadr[mesh]), int(model.mesh_facenum[mesh])
    uv = np.asarray(model.mesh_texcoord, dtype=np.float64)[
        adr + np.asarray(model.mesh_facetexcoord[f0 : f0 + nf], dtype=np.int64)
    ]
    uv[..., 1] = 1.0 - uv[..., 1]  # OpenGL's t counts rows from the image's first (top) one
    return uv


def _pixels(model: Any, tex: int) -> np.ndarray:
    """A texture as MuJoCo compiled it (builtin checker, gradient, flat, or an image: all are pixels by then)."""
    w, h = int(model.tex_width[tex]), int(model.tex_height[tex])
    channels = texture_channels(model, tex)
    adr = int(model.tex_adr[tex])
    pixels = np.asarray(model.tex_data[adr : adr + w * h * channels], dtype=np.float32).reshape(h, w, channels) / 255.0
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., : min(channels, 3)] = pixels[..., :3]
    if channels == 1:
        rgba[..., 1] = rgba[..., 2] = pixels[..., 0]
    return rgba[::-1].copy()
