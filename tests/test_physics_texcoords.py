"""MuJoCo's texture coordinates as numbers (visualenv/physics/texcoords.py), against render_gl3.c and OpenGL's cube map table."""

from __future__ import annotations

import numpy as np
import pytest

from visualenv.physics.texcoords import cube_uv, planar_uv


def test_a_2d_texture_follows_mujocos_texgen_planes() -> None:
    """s = 0.5 scl_x x - 0.5, t = -0.5 scl_y y - 0.5 (t from the image's top row); Blender's v = 1 - t."""
    uv = planar_uv(np.array([[-1.0, 1.0, 0.3], [1.0, -1.0, -2.0], [0.5, 0.0, 0.0]]), (1.0, 2.0))
    np.testing.assert_allclose(uv, [[-1.0, 2.5], [0.0, 0.5], [-0.25, 1.5]], atol=1e-12)


def unit_cube_face(axis: int, sign: float) -> np.ndarray:
    """The four corners of the unit cube's face at `sign` along `axis`."""
    a, b = [k for k in range(3) if k != axis]
    corners = np.zeros((4, 3))
    corners[:, axis] = sign
    corners[:, a] = [-1, 1, 1, -1]
    corners[:, b] = [-1, -1, 1, 1]
    return corners


@pytest.mark.parametrize(("face", "axis", "sign", "point", "st"), [
    (0, 0, 1.0, (1.0, -0.5, 0.5), (0.25, 0.75)),    # +X: s = -z, t = -y
    (1, 0, -1.0, (-1.0, -0.5, 0.5), (0.75, 0.75)),  # -X: s = +z, t = -y
    (2, 1, 1.0, (-0.5, 1.0, 0.5), (0.25, 0.75)),    # +Y: s = +x, t = +z
    (3, 1, -1.0, (-0.5, -1.0, 0.5), (0.25, 0.25)),  # -Y: s = +x, t = -z
    (4, 2, 1.0, (-0.5, 0.5, 1.0), (0.25, 0.25)),    # +Z: s = +x, t = -y
    (5, 2, -1.0, (-0.5, 0.5, -1.0), (0.75, 0.25)),  # -Z: s = -x, t = -y
])
def test_a_cube_texture_picks_the_face_and_its_coordinates_as_opengl_does(face: int, axis: int, sign: float, point: tuple, st: tuple) -> None:
    """Each face of a box reads its own face of the cube map, stacked from the top of the image (face 0) down."""
    points = np.vstack([unit_cube_face(axis, sign), [point]])
    # one quad (the face) and one triangle made of the point twice and the face's centre, which sits on the same face
    centre = np.zeros(3)
    centre[axis] = sign
    points = np.vstack([points, [centre]])
    uv = cube_uv(points, np.array([0, 4]), np.array([0, 1, 2, 3, 4, 4, 5]), faces=6, texels=1000)
    s, t = st
    np.testing.assert_allclose(uv[4], [s, 1.0 - (face + t) / 6], atol=1e-9)
    np.testing.assert_allclose(uv[6], [0.5, 1.0 - (face + 0.5) / 6], atol=1e-9)
    assert np.all((uv[:4, 1] >= 1.0 - (face + 1) / 6) & (uv[:4, 1] <= 1.0 - face / 6))  # the whole face stays in its band


def test_one_cube_face_for_all_six_and_the_edges_stay_inside_the_face() -> None:
    """A cube texture of one square image repeats it on every face; corners keep half a texel from the face's edge."""
    uv = cube_uv(unit_cube_face(2, 1.0), np.array([0]), np.array([0, 1, 2, 3]), faces=1, texels=4)
    assert uv.min() == pytest.approx(0.125) and uv.max() == pytest.approx(0.875)
