"""MuJoCo's texture mapping as numbers: where each corner of a geom's polygons samples its material's texture.

MuJoCo's OpenGL renderer (``settexture`` in ``render_gl3.c``) generates texture
coordinates from each vertex's *object coordinates*: the coordinates of the unit
shape it scales by the geom's size (a box is [-1, 1]^3, a sphere the unit
sphere, a cylinder radius 1 from z=-1 to 1, a capsule's caps unit hemispheres
about their own centres), or the vertices themselves for planes and meshes.

* ``2d``: ``s = 0.5 scl_x x - 0.5`` and ``t = -0.5 scl_y y - 0.5``, repeated
  (``scl`` is the material's ``texrepeat``, over the size for planes and meshes,
  times the size with ``texuniform``): a projection along the geom's z axis.
* ``cube``: ``(x, y, z)`` (times the size with ``texuniform``) is a direction
  looked up in a cube map, as OpenGL does: the largest component picks one of
  the six faces (+X, -X, +Y, -Y, +Z, -Z, MuJoCo's order in ``tex_data``), the
  other two divided by it place the point on that face. A box's faces each show
  one face of the cube map; round shapes show it projected from their centre.

Blender interpolates texture coordinates linearly across a polygon, while OpenGL
divides per pixel for cube maps: exact on flat faces facing an axis (boxes),
close on the finely divided round shapes. A polygon that straddles two faces of
the cube takes the face its centre points to (its corners clamped to that face).
Coordinates returned here are Blender UVs (v up, images stored bottom row first).
"""

from __future__ import annotations

import numpy as np

#: OpenGL's cube map selection (OpenGL 4.6 core, table 8.19), per face in MuJoCo's order:
#: (major axis, its sign, (axis, sign) of s_c, (axis, sign) of t_c)
CUBE_FACES = (
    (0, 1.0, (2, -1.0), (1, -1.0)),  # +X
    (0, -1.0, (2, 1.0), (1, -1.0)),  # -X
    (1, 1.0, (0, 1.0), (2, 1.0)),  # +Y
    (1, -1.0, (0, 1.0), (2, -1.0)),  # -Y
    (2, 1.0, (0, 1.0), (1, -1.0)),  # +Z
    (2, -1.0, (0, -1.0), (1, -1.0)),  # -Z
)
#: CUBE_FACES as rows of numbers: major axis, its sign, s_c's axis and sign, t_c's axis and sign
_FACE_TABLE = np.array([(a, sg, sa, ss, ta, ts) for a, sg, (sa, ss), (ta, ts) in CUBE_FACES])


def _face_of(directions: np.ndarray) -> np.ndarray:
    """The cube face (MuJoCo's order) each direction (n, 3) points to: its largest component and that one's sign."""
    axis = np.argmax(np.abs(directions), axis=1)
    return 2 * axis + (directions[np.arange(len(directions)), axis] < 0)


def _on_face(points: np.ndarray, face: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s_c, t_c), in [-1, 1] on the face, of each point (n, 3) on its cube face (n,), as OpenGL's cube map places it."""
    table = _FACE_TABLE[face]
    rows = np.arange(len(points))
    major = np.maximum(points[rows, table[:, 0].astype(int)] * table[:, 1], 1e-9)
    return (
        points[rows, table[:, 2].astype(int)] * table[:, 3] / major,
        points[rows, table[:, 4].astype(int)] * table[:, 5] / major,
    )


def planar_uv(points: np.ndarray, scale: tuple[float, float]) -> np.ndarray:
    """(n, 2) Blender UVs of a 2-D texture at object coordinates `points` (n, 3); the image repeats outside [0, 1]."""
    s = 0.5 * scale[0] * points[:, 0] - 0.5
    t = -0.5 * scale[1] * points[:, 1] - 0.5  # OpenGL's t runs down the image's rows from its first (top) one
    return np.stack([s, 1.0 - t], axis=1)


def cube_uv(
    points: np.ndarray, loop_starts: np.ndarray, loop_vertex: np.ndarray, *, faces: int, texels: int
) -> np.ndarray:
    """(loops, 2) Blender UVs in a cube texture stored as `faces` (6, or 1 repeated) square images of `texels` a side,
    stacked from the top (face 0) down, for polygons whose loops start at `loop_starts` and visit `loop_vertex`.

    `points` (n, 3) are the vertices' object coordinates (already scaled for ``texuniform``).
    """
    corners = points[loop_vertex]
    counts = np.diff(np.append(loop_starts, len(loop_vertex)))
    centres = np.add.reduceat(corners, loop_starts, axis=0) / counts[:, None] if len(loop_starts) else np.zeros((0, 3))
    face = np.repeat(_face_of(centres), counts)
    sc, tc = _on_face(corners, face)
    inset = 0.5 / max(texels, 1)  # OpenGL clamps to the face's edge texels: stay half a texel inside the face
    s = np.clip(0.5 * (sc + 1.0), inset, 1.0 - inset)
    t = np.clip(0.5 * (tc + 1.0), inset, 1.0 - inset)
    band = face if faces == 6 else np.zeros_like(face)
    return np.stack([s, 1.0 - (band + t) / faces], axis=1)


#: the most texels across an equirectangular sky made from a cube map (4 per cube texel, up to this)
SKY_WIDTH = 1024
#: the most texels a side of a skybox face keeps: larger faces are averaged in blocks, as MuJoCo's mipmaps average a
#: face's texels under each pixel of an observation (dm_control's 800-texel sky: its 1 % of white dots a faint haze, not stars)
SKY_FACE_TEXELS = 256


def average_faces(pixels: np.ndarray, most: int = SKY_FACE_TEXELS) -> np.ndarray:
    """A cube map (faces stacked, bottom row first) with each face averaged in square blocks to at most `most` texels a
    side, by the smallest block that divides the face (the map unchanged when it is small enough, or no block divides it)."""
    texels = pixels.shape[1]
    block = (
        next((b for b in range(2, texels + 1) if texels % b == 0 and texels // b <= most), 1) if texels > most else 1
    )
    if block == 1:
        return pixels
    rows, channels = pixels.shape[0], pixels.shape[2]
    return (
        pixels.reshape(rows // block, block, texels // block, block, channels)
        .mean(axis=(1, 3), dtype=np.float64)
        .astype(pixels.dtype)
    )


def cube_to_equirect(pixels: np.ndarray, *, width: int | None = None) -> np.ndarray:
    """A skybox cube map as the equirectangular image Blender's Environment Texture maps (z up), bottom row first.

    `pixels` is the cube texture as :class:`~visualenv.physics.scene.GeomShape` holds
    one: six square faces stacked from the top (MuJoCo's order), or one face for all
    six, bottom row first. MuJoCo draws its skybox turned so the cube map's +Y (where
    a gradient puts ``rgb1``) is the world's +Z: a direction ``(x, y, z)`` samples the
    cube map at ``(x, z, -y)``. Blender's equirectangular mapping puts azimuth
    ``atan2(y, x) = 0`` at the image's centre column and the zenith at its top row.
    Texels are taken nearest (Blender interpolates the image it is given), from faces averaged to at most
    :data:`SKY_FACE_TEXELS` a side (:func:`average_faces`).
    """
    pixels = average_faces(pixels)
    texels = pixels.shape[1]
    faces = pixels.shape[0] // texels
    width = width or min(4 * texels, SKY_WIDTH)
    height = max(width // 2, 1)
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    azimuth = (0.5 - u)[None, :] * 2.0 * np.pi
    elevation = (v - 0.5)[:, None] * np.pi
    d = np.stack(
        np.broadcast_arrays(
            np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)
        ),
        axis=-1,
    ).reshape(-1, 3)
    tex = np.stack([d[:, 0], d[:, 2], -d[:, 1]], axis=1)
    face = _face_of(tex)
    sc, tc = _on_face(tex, face)
    col = np.clip((0.5 * (sc + 1.0) * texels).astype(int), 0, texels - 1)
    row = np.clip((0.5 * (tc + 1.0) * texels).astype(int), 0, texels - 1)  # from the face's top row
    band = face if faces == 6 else np.zeros_like(face)
    top_first = pixels[::-1]
    return top_first[band * texels + row, col].reshape(height, width, pixels.shape[2]).astype(np.float32)
