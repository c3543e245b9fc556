"""MuJoCo's texture coordinates as numbers (visualenv/physics/texcoords.py), against render_gl3.c and OpenGL's cube map table."""

from __future__ import annotations

import numpy as np
import pytest

from visualenv.physics.texcoords import cube_to_equirect, cube_uv, planar_uv


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


@pytest.mark.parametrize(
    ("face", "axis", "sign", "point", "st"),
    [
        (0, 0, 1.0, (1.0, -0.5, 0.5), (0.25, 0.75)),  # +X: s = -z, t = -y
        (1, 0, -1.0, (-1.0, -0.5, 0.5), (0.75, 0.75)),  # -X: s = +z, t = -y
        (2, 1, 1.0, (-0.5, 1.0, 0.5), (0.25, 0.75)),  # +Y: s = +x, t = +z
        (3, 1, -1.0, (-0.5, -1.0, 0.5), (0.25, 0.25)),  # -Y: s = +x, t = -z
        (4, 2, 1.0, (-0.5, 0.5, 1.0), (0.25, 0.25)),  # +Z: s = +x, t = -y
        (5, 2, -1.0, (-0.5, 0.5, -1.0), (0.75, 0.25)),  # -Z: s = -x, t = -y
    ],
)
def test_a_cube_texture_picks_the_face_and_its_coordinates_as_opengl_does(
    face: int, axis: int, sign: float, point: tuple, st: tuple
) -> None:
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
    assert np.all(
        (uv[:4, 1] >= 1.0 - (face + 1) / 6) & (uv[:4, 1] <= 1.0 - face / 6)
    )  # the whole face stays in its band


def test_one_cube_face_for_all_six_and_the_edges_stay_inside_the_face() -> None:
    """A cube texture of one square image repeats it on every face; corners keep half a texel from the face's edge."""
    uv = cube_uv(unit_cube_face(2, 1.0), np.array([0]), np.array([0, 1, 2, 3]), faces=1, texels=4)
    assert uv.min() == pytest.approx(0.125) and uv.max() == pytest.approx(0.875)


def test_a_skybox_becomes_an_equirectangular_sky_with_the_cube_maps_plus_y_up() -> None:
    """Six faces of one grey level each: each world direction shows the face MuJoCo's z-up skybox puts there."""
    texels = 4
    levels = np.arange(6) / 10.0  # face k (MuJoCo's order +X, -X, +Y, -Y, +Z, -Z) is k / 10
    top_first = np.repeat(levels, texels)[:, None, None] * np.ones((6 * texels, texels, 4))
    sky = cube_to_equirect(top_first[::-1], width=64)  # the texture as GeomShape holds it: bottom row first
    assert sky.shape == (32, 64, 4)
    level = np.round(sky[..., 0] * 10).astype(int)  # the face's index
    assert set(level[-1]) == {2}  # zenith (top row, world +z): the cube's +Y, where a gradient puts rgb1
    assert set(level[0]) == {3}  # nadir: -Y
    # on the horizon, Blender's azimuth atan2(y, x) is 0 at the centre column and grows leftwards
    horizon = level[16]
    assert horizon[32] == 0  # world +x: +X
    assert horizon[16] == 5  # world +y: -Z
    assert horizon[48] == 4  # world -y: +Z
    assert horizon[0] == horizon[63] == 1  # world -x: -X


def test_a_gradient_skybox_is_rgb1_above_and_rgb2_below() -> None:
    mujoco = pytest.importorskip("mujoco")
    from visualenv.physics.scene import _pixels

    model = mujoco.MjModel.from_xml_string(
        '<mujoco><asset><texture type="skybox" builtin="gradient" rgb1="1 1 1" '
        'rgb2="0 0 0" width="16" height="16"/></asset><worldbody/></mujoco>'
    )
    level = cube_to_equirect(_pixels(model, 0))[..., 0].mean(axis=1)  # by row, bottom first
    assert level[-1] > 0.9 and level[0] < 0.1
    assert np.all(np.diff(level) > -0.03)  # brighter upwards all the way (nearest texels: steps, no dips)


def test_a_large_skybox_face_is_averaged_as_mipmaps_average_it():
    """dm_control's sky: 800-texel faces with 1 % white dots. Averaged in 4 x 4 blocks to 200 texels (at most 256),
    the dots become a faint haze of the same mean; a small map is kept as it is."""
    from visualenv.physics.texcoords import SKY_FACE_TEXELS, average_faces

    rng = np.random.default_rng(0)
    faces = np.full((6 * 800, 800, 4), 0.3, np.float32)
    faces[..., :3][rng.random((6 * 800, 800)) < 0.01] = 1.0
    averaged = average_faces(faces)
    assert averaged.shape == (6 * 200, 200, 4) and 200 <= SKY_FACE_TEXELS
    assert abs(averaged[..., 0].mean() - faces[..., 0].mean()) < 1e-4
    assert averaged[..., 0].max() < 0.5 < faces[..., 0].max()  # no texel a white dot
    small = faces[: 6 * 100, :100]
    assert average_faces(small) is small
