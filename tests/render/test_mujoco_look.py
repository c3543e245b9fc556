"""physics.look 'mujoco': a model lit and coloured as MuJoCo's OpenGL renderer draws it, evenly, at 1 sample.

Real renders at the training preset (1 sample, no bounces), asserted on pixels
against MuJoCo's lighting arithmetic (render_gl3.c: colour times the sum of
every light's ambient and diffuse terms, plus the headlight's specular, written
as it is): a box face facing the camera is one colour to a level, a spot light
does not fade with distance, a light that casts shadows casts them, and
Gymnasium's humanoid and hopper (which were 35 to 45 % black at 84x84 under
Blender's light) show their bodies' colour.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

import visualenv  # noqa: E402

pytestmark = pytest.mark.blender

BOX = """\
<mujoco>
  <visual><headlight ambient="{a} {a} {a}" diffuse="{d} {d} {d}" specular="{s} {s} {s}" active="{on}"/></visual>
  <worldbody>
    {lights}
    <camera name="eye" pos="0 -3 0" xyaxes="1 0 0 0 0 1"/>
    <geom name="floor" type="plane" pos="0 0 -0.5" size="3 3 .1" rgba=".5 .5 .5 1"/>
    <body name="block"><joint name="slide" type="slide" axis="1 0 0"/>
      <geom name="block" type="box" size=".5 .5 .5" rgba=".8 .6 .4 1"/></body>
  </worldbody>
  <actuator><motor joint="slide"/></actuator>
</mujoco>
"""
SPEC = """\
id: Look-v0
physics: {{model: model.xml{look}}}
observation:
  cameras:
    eye: {{camera: {camera}, resolution: [{size}, {size}], color: rgb}}
    mask: {{camera: {camera}, resolution: [{size}, {size}], color: segmentation}}
reward: 0.0
"""


def frame(
    tmp_path: Path, model: str, *, camera: str = "eye", size: int = 32, look: str = "", extra: str = ""
) -> tuple[np.ndarray, np.ndarray, dict]:
    """The first frame (ints) and segmentation mask of `model` seen through `camera`, and the mask's ids (`extra`: more
    of the spec, appended)."""
    (tmp_path / "model.xml").write_text(model, encoding="utf-8")
    spec = tmp_path / "look.yaml"
    spec.write_text(
        SPEC.format(camera=camera, size=size, look=f", look: {look}" if look else "") + extra, encoding="utf-8"
    )
    env = visualenv.make(spec)
    try:
        obs, _ = env.reset(seed=0)
        return obs["eye"].astype(int), obs["mask"][..., 0], env.unwrapped.segmentation_ids
    finally:
        env.close()


def inside(mask: np.ndarray) -> np.ndarray:
    """The pixels of `mask` whose four neighbours are in it too: off the silhouette, where a pixel's one sample may miss."""
    out = mask.copy()
    out[0, :] = out[-1, :] = out[:, 0] = out[:, -1] = False
    for shift in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        out &= np.roll(mask, shift, axis=(0, 1))
    return out


def level(value: float) -> int:
    """A colour's byte as MuJoCo writes it (no display transform)."""
    return int(np.floor(min(value, 1.0) * 255 + 0.5))


def test_a_face_shows_its_colour_times_the_headlights_ambient_and_diffuse_terms(tmp_path: Path) -> None:
    """No light but the headlight (ambient .2, diffuse .5, no specular): the face toward the camera is rgba * 0.7,
    every pixel of it, to a level (under Blender's light it was a sun's noisy estimate, and sRGB)."""
    model = BOX.format(a=0.2, d=0.5, s=0, on=1, lights="")
    image, mask, ids = frame(tmp_path, model)
    face = inside(mask == ids["block"])
    assert face.sum() >= 100
    expected = [level(c * 0.7) for c in (0.8, 0.6, 0.4)]  # (143, 107, 71)
    assert np.abs(image[face] - expected).max() <= 1, (image[face].min(axis=0), image[face].max(axis=0), expected)
    floor = inside(mask == ids["world"])
    assert floor.sum() >= 20  # seen edge-on below the block: n.l = 0, only the ambient term
    assert np.abs(image[floor] - level(0.5 * 0.2)).max() <= 2, np.unique(image[floor])


def test_the_headlights_specular_term_is_a_highlight_at_the_faces_centre(tmp_path: Path) -> None:
    """MuJoCo's Blinn-Phong highlight (headlight specular .4, the geom's specular .5, shininess .5: exponent 64) adds
    .2 where the face's normal halves the view and the light, at its centre, and fades off it."""
    image, mask, ids = frame(tmp_path, BOX.format(a=0.2, d=0.5, s=0.4, on=1, lights=""), size=33)
    centre = image[16, 16]
    assert np.abs(centre - [level(c * 0.7 + 0.2) for c in (0.8, 0.6, 0.4)]).max() <= 2, centre
    corner = image[11, 11]  # 7 degrees off the axis: cos(3.5 deg) ** 64 = 0.89, then less
    assert (corner < centre - 5).all() and (corner > [level(c * 0.7) for c in (0.8, 0.6, 0.4)]).all(), (corner, centre)


def test_a_lit_face_is_even_at_one_sample_with_the_models_light_and_shadows(tmp_path: Path) -> None:
    """The model's light (directional, 45 degrees down toward the block, casting shadows) plus MuJoCo's default
    headlight, in the default world, at the training preset: the face's pixels are one colour within 2 levels,
    rgba * (ambient .1 + headlight .4 + light .6 * cos 45)."""
    light = '<light name="sun" directional="true" dir="0 1 -1" diffuse=".6 .6 .6" specular="0 0 0"/>'
    model = BOX.format(a=0.1, d=0.4, s=0, on=1, lights=light)
    image, mask, ids = frame(tmp_path, model, size=48)
    face = inside(mask == ids["block"])
    assert face.sum() >= 250
    pixels = image[face]
    assert np.ptp(pixels, axis=0).max() <= 2, (pixels.min(axis=0), pixels.max(axis=0))
    light_term = 0.1 + 0.4 + 0.6 * np.sqrt(0.5)
    assert np.abs(pixels.mean(axis=0) - [c * light_term * 255 for c in (0.8, 0.6, 0.4)]).max() <= 2, pixels.mean(axis=0)


def test_a_spot_light_keeps_mujocos_cone_and_does_not_fade_with_distance(tmp_path: Path) -> None:
    """A spot light straight above a plane (headlight off): the spot under it is rgba * diffuse at 1 m and at 3 m
    (MuJoCo's default attenuation is none), and dark beyond its cutoff."""

    def seen(height: float) -> np.ndarray:
        model = f"""<mujoco><visual><headlight active="0"/></visual><worldbody>
          <light name="spot" pos="0 0 {height}" dir="0 0 -1" diffuse=".7 .7 .7" cutoff="20" exponent="2" castshadow="false"/>
          <camera name="down" pos="0 0 6" xyaxes="1 0 0 0 1 0" fovy="60"/>
          <geom name="floor" type="plane" size="5 5 .1" rgba=".6 .6 .6 1"/>
          <body name="probe" pos="9 9 9"><joint name="slide" type="slide" axis="1 0 0"/><geom type="sphere" size=".1"/></body>
        </worldbody><actuator><motor joint="slide"/></actuator></mujoco>"""
        return frame(tmp_path, model, camera="down", size=33)[0]

    near, far = seen(1.0), seen(3.0)
    spot = level(0.6 * 0.7)  # within the centre pixel the angle reaches 6 degrees at 1 m: cos**3 = 0.98
    assert abs(near[16, 16, 0] - spot) <= 3 and abs(far[16, 16, 0] - spot) <= 3, (near[16, 16], far[16, 16])
    assert near[16, 29, 0] == 0 and near[3, 16, 0] == 0  # 1 m below it, 1.5 m off its axis: past 20 degrees


def test_a_light_that_casts_shadows_darkens_what_it_cannot_reach(tmp_path: Path) -> None:
    """A directional light 45 degrees down toward +x, seen from above: the block's shadow falls on the floor beside it,
    where the floor gets only the ambient and headlight terms; with castshadow false the floor there is lit."""

    def top_view(cast: str) -> tuple[np.ndarray, np.ndarray, dict]:
        light = f'<light name="sun" directional="true" dir="1 0 -1" diffuse=".6 .6 .6" castshadow="{cast}"/>'
        model = BOX.format(a=0.1, d=0.4, s=0, on=1, lights=light).replace(
            '<camera name="eye" pos="0 -3 0" xyaxes="1 0 0 0 0 1"/>',
            '<camera name="eye" pos="0 0 6" xyaxes="1 0 0 0 1 0" fovy="60"/>',
        )
        return frame(tmp_path, model, size=48)

    shaded, mask, ids = top_view("true")
    lit, _, _ = top_view("false")
    floor = inside(mask == ids["world"])
    changed = floor & (np.abs(shaded - lit).max(axis=2) > 10)
    # the shadow falls beside the block, toward +x (the light comes from -x): seen from above, to its right
    assert changed.sum() >= 20, changed.sum()
    cols = np.nonzero(changed)[1]
    block_cols = np.nonzero(mask == ids["block"])[1]
    assert cols.mean() > block_cols.mean()
    assert (shaded[changed] < lit[changed]).all()
    expected_shadow = level(0.5 * (0.1 + 0.4))  # ambient and the headlight (the floor faces the camera) only
    assert np.abs(shaded[changed] - expected_shadow).max() <= 2


@pytest.mark.parametrize("model", ["humanoid", "hopper"])
def test_gymnasiums_bodies_show_their_colour_not_black(tmp_path: Path, model: str) -> None:
    """Gymnasium's humanoid and hopper through their track camera at 84x84: a few percent of their bodies' pixels at
    most below 10 of 255 (Blender's light left 44 % and 36 % of them black: a sun from above, nothing on the sides
    the camera sees), as MuJoCo's headlight lights them."""
    spec = tmp_path / "body.yaml"
    spec.write_text(
        f"""id: Body-v0
physics: {{model: "package:gymnasium.envs.mujoco/assets/{model}.xml"}}
observation:
  cameras:
    eye: {{camera: track, resolution: [84, 84], color: rgb}}
    mask: {{camera: track, resolution: [84, 84], color: segmentation}}
reward: 0.0
""",
        encoding="utf-8",
    )
    env = visualenv.make(spec)
    try:
        obs, _ = env.reset(seed=0)
        ids = env.unwrapped.segmentation_ids
    finally:
        env.close()
    mask = obs["mask"][..., 0]
    body = (mask != 0) & (mask != ids["world"])
    assert body.sum() >= 100, body.sum()
    brightest = obs["eye"][body].max(axis=1)
    assert (brightest < 10).mean() <= 0.03, (brightest < 10).mean()
    assert np.median(brightest) >= 60, np.median(brightest)


def test_memory_and_file_readback_write_the_same_raw_bytes(tmp_path: Path) -> None:
    """The in-memory readback writes MuJoCo's look as Blender's 'Raw' view writes the file, for rgb and grayscale."""
    (tmp_path / "model.xml").write_text(BOX.format(a=0.2, d=0.5, s=0.3, on=1, lights=""), encoding="utf-8")
    frames = {}
    for color in ("rgb", "grayscale"):
        spec = tmp_path / f"{color}.yaml"
        spec.write_text(
            f"id: Raw-v0\nphysics: {{model: model.xml}}\nobservation: {{camera: eye, resolution: [24, 24], color: {color}}}\n"
            "render: {noise: shared}\nreward: 0.0\n",
            encoding="utf-8",
        )
        for readback in ("memory", "file"):
            env = visualenv.make(spec, readback=readback)
            try:
                frames[color, readback] = env.reset(seed=0)[0]
            finally:
                env.close()
        assert np.array_equal(frames[color, "memory"], frames[color, "file"]), color
    centre = frames["rgb", "file"][12, 12].astype(int)  # MuJoCo's bytes, not sRGB's (which would be 230 and up)
    assert np.abs(centre - [level(c * 0.7 + 0.15) for c in (0.8, 0.6, 0.4)]).max() <= 1, centre


def test_the_physical_look_keeps_blenders_light_and_srgb(tmp_path: Path) -> None:
    """physics.look 'physical' draws as before MuJoCo's look: the same block face in sRGB under a sun standing in for
    the headlight, brighter than MuJoCo's byte arithmetic (a shipped agent was trained on these frames)."""
    model = BOX.format(a=0.2, d=0.5, s=0, on=1, lights="")
    mujoco_look, mask, ids = frame(tmp_path, model)
    physical, _, _ = frame(tmp_path, model, look="physical")
    face = inside(mask == ids["block"])
    assert physical[face].mean() > mujoco_look[face].mean() + 20


def test_a_spec_object_standing_for_a_body_is_lit_as_a_geom(tmp_path: Path) -> None:
    """An object the spec declares under the block's name (a cube of colour .2 .6 .4) stands for it and is lit as
    MuJoCo lights a geom without a material: its face toward the camera rgba * (ambient + diffuse), evenly (Blender's
    light alone left it black: the model has no light)."""
    own = """scene:
  objects:
    block: {primitive: cube, size: [1, 1, 1], material: {color: [0.2, 0.6, 0.4]}}
"""
    image, mask, ids = frame(tmp_path, BOX.format(a=0.2, d=0.5, s=0, on=1, lights=""), extra=own)
    face = inside(mask == ids["block"])
    assert face.sum() >= 100
    assert np.abs(image[face] - [level(c * 0.7) for c in (0.2, 0.6, 0.4)]).max() <= 1


def test_a_planes_checks_lie_where_mujoco_draws_them(tmp_path: Path) -> None:
    """MuJoCo 3.17 lays a finite plane's 2-D texture from the plane's (-x, +y) corner: a 0.7 x 0.45 m plane with a
    black-and-white checker repeated twice per 2 m (texuniform) has its checks' edges at x = -0.2 and 0.3 and at
    y = -0.05, measured with mujoco.Renderer (from the centre they would be at x = -0.5, 0, 0.5 and y = 0)."""
    model = """<mujoco><visual><headlight ambient="1 1 1" diffuse="0 0 0" specular="0 0 0"/></visual>
      <asset><texture name="g" type="2d" builtin="checker" rgb1="1 1 1" rgb2="0 0 0" width="64" height="64"/>
        <material name="g" texture="g" texrepeat="2 2" texuniform="true"/></asset>
      <worldbody><geom name="floor" type="plane" size=".7 .45 .1" material="g"/><camera name="down" pos="0 0 2" fovy="60"/>
        <body name="probe" pos="9 9 9"><joint name="slide" type="slide" axis="1 0 0"/><geom type="sphere" size=".1"/></body>
      </worldbody><actuator><motor joint="slide"/></actuator></mujoco>"""
    image = frame(tmp_path, model, camera="down", size=100)[0][..., 0]
    metres = (np.arange(100) + 0.5 - 50) * (
        2 * 2 * np.tan(np.radians(30)) / 100
    )  # the floor under each column's centre
    along_x = image[50] > 128  # the row at y = 0 (rows run down the image: -y)
    edges_x = metres[:-1][np.diff(along_x)] + (metres[1] - metres[0]) / 2
    inside = edges_x[np.abs(edges_x) < 0.65]
    assert inside.shape == (2,) and np.allclose(inside, [-0.2, 0.3], atol=0.03), edges_x
    along_y = image[:, 30] > 128  # the column at x = -0.46, within one check along x
    edges_y = -(metres[:-1][np.diff(along_y)] + (metres[1] - metres[0]) / 2)
    inside = edges_y[np.abs(edges_y) < 0.4]
    assert inside.shape == (1,) and np.allclose(inside, [-0.05], atol=0.03), edges_y


def test_the_lit_colour_is_clamped_before_the_texture_multiplies_it(tmp_path: Path) -> None:
    """OpenGL clamps a vertex's lit colour to 1 before the texture multiplies it: a white box with a grey texture
    (.5 on the face toward the camera) under ambient .4 and diffuse .8 shows .5, not .6 (dm_control's floors)."""
    model = (
        BOX.format(a=0.4, d=0.8, s=0, on=1, lights="")
        .replace(
            "<worldbody>",
            '<asset><texture name="t" type="cube" builtin="flat" rgb1=".5 .5 .5" rgb2=".5 .5 .5" width="8" height="8"/>'
            '<material name="m" texture="t"/></asset><worldbody>',
        )
        .replace('rgba=".8 .6 .4 1"/>', 'rgba="1 1 1 1" material="m"/>')
    )
    image, mask, ids = frame(tmp_path, model)
    face = inside(mask == ids["block"])
    assert face.sum() >= 100 and np.abs(image[face] - level(0.5)).max() <= 1, np.unique(image[face])


def test_no_surface_lights_another_at_any_bounce_count(tmp_path: Path) -> None:
    """MuJoCo draws no light from one surface onto another: with bounces (the quality preset: 16 samples, 4 bounces),
    the block's face toward the camera, which the model's light (toward +x and down) misses while it lights the floor
    in front of it, stays rgba * (ambient + headlight), as at 1 sample without bounces."""
    light = '<light name="sun" directional="true" dir="1 0 -1" diffuse=".9 .9 .9" castshadow="false"/>'
    image, mask, ids = frame(
        tmp_path, BOX.format(a=0.1, d=0.4, s=0, on=1, lights=light), extra="render: {preset: quality}\n"
    )
    face = inside(mask == ids["block"])
    assert face.sum() >= 100
    expected = [level(c * 0.5) for c in (0.8, 0.6, 0.4)]
    assert np.abs(image[face] - expected).max() <= 1, (image[face].max(axis=0), expected)
