"""An MJCF model drawn by Blender: geoms become objects that take MuJoCo's poses; hidden groups stay hidden; model cameras follow.

Real renders at tiny sizes, asserted on pixels: the pendulum's pole (cyan in
Gymnasium's XML) stands above the cart, and leans right when the hinge turns;
a geom in group 3 (hidden by MuJoCo's viewer) never shows; HalfCheetah's
``track`` camera keeps the running cheetah in view.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

import visualenv  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.errors import SpecError  # noqa: E402
from visualenv.render.frames import Frames

pytestmark = pytest.mark.blender

POLE = """\
id: Pole-v0
params: {angle: 0.0}
physics:
  model: package:gymnasium.envs.mujoco/assets/inverted_pendulum.xml
  reset: {values: {qpos_hinge: angle}}
scene:
  world: {color: [0.02, 0.02, 0.02]}
  objects:
    Camera: {camera: perspective, location: [0, -3, 0.3], look_at: [0, 0, 0.3], lens: 35}
observation: {camera: Camera, resolution: [48, 48], color: rgb}
reward: 1.0
"""


def cyan(image: np.ndarray) -> np.ndarray:
    """Where the pole is: green and blue well above red (its rgba is 0 0.7 0.7)."""
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (g > r + 40) & (b > r + 40)


def first_frame(spec: Path) -> np.ndarray:
    """The observation of the spec's env after reset(seed=0), as ints (the env closed)."""
    env = VisualEnv(spec)
    try:
        return env.reset(seed=0)[0].astype(int)
    finally:
        env.close()


def pole_pixels(tmp_path: Path, angle: float) -> np.ndarray:
    path = tmp_path / "pole.yaml"
    path.write_text(POLE, encoding="utf-8")
    env = visualenv.make(path, params={"angle": angle})
    try:
        obs, _ = env.reset(seed=0)
        assert env.unwrapped.data.qpos[1] == angle
        return cyan(obs)
    finally:
        env.close()


def test_the_pole_stands_then_leans_where_the_hinge_turns_it(tmp_path: Path) -> None:
    upright, leaning = pole_pixels(tmp_path, 0.0), pole_pixels(tmp_path, 1.0)
    assert upright.sum() >= 8 and leaning.sum() >= 8, (upright.sum(), leaning.sum())
    rows_u, cols_u = np.nonzero(upright)
    rows_l, cols_l = np.nonzero(leaning)
    # upright: a column about the image's centre, reaching higher than the leaning pole does
    assert abs(cols_u.mean() - 23.5) < 3, cols_u.mean()
    assert cols_l.mean() > cols_u.mean() + 4, (
        cols_u.mean(),
        cols_l.mean(),
    )  # a positive hinge angle turns +z to +x: right
    assert rows_u.min() < rows_l.min() - 2, (rows_u.min(), rows_l.min())


HIDDEN = """\
<mujoco>
  <worldbody>
    <light directional="true" pos="0 0 3" dir="0 0 -1"/>
    <body name="ball" pos="-0.3 0 0">
      <freejoint/>
      <geom name="visible" type="sphere" size="0.2" rgba="0 1 0 1"/>
    </body>
    <geom name="hidden" type="box" size="0.2 0.2 0.2" pos="0.3 0 0" rgba="1 0 0 1" group="3"/>
    <geom name="shown" type="ellipsoid" size="0.1 0.1 0.2" pos="0.3 0 0.5" rgba="0 0 1 1" group="2"/>
    <camera name="front" pos="0 -2 0.2" xyaxes="1 0 0 0 0 1"/>
  </worldbody>
</mujoco>
"""


def test_hidden_groups_stay_hidden_and_the_models_camera_sees(tmp_path: Path) -> None:
    (tmp_path / "m.xml").write_text(HIDDEN, encoding="utf-8")
    spec = tmp_path / "s.yaml"
    spec.write_text(
        textwrap.dedent("""\
        id: Hidden-v0
        physics: {model: m.xml, frame_skip: 5}
        scene: {world: {color: [0, 0, 0]}}
        observation: {camera: front, resolution: [32, 32], color: rgb}
        actions: {discrete: [{}]}
        reward: 0
        """),
        encoding="utf-8",
    )
    env = VisualEnv(spec)
    try:
        obs, _ = env.reset(seed=0)
        img = obs.astype(int)
        r, g, b = img[..., 0], img[..., 1], img[..., 2]
        assert ((g > 60) & (g > r + 40) & (g > b + 40)).sum() > 5  # the sphere (group 0)
        assert ((b > 60) & (b > r + 40) & (b > g + 40)).sum() > 2  # the ellipsoid (group 2)
        assert ((r > 60) & (r > g + 40) & (r > b + 40)).sum() == 0  # the box of group 3: hidden
        left = (g > r + 40)[:, :16].sum()
        assert left > (g > r + 40)[:, 16:].sum()  # the sphere is left of centre, where the body put it
        for _ in range(30):  # the free body falls: its pixels move down
            obs, *_ = env.step(0)
        rows = np.nonzero((obs[..., 1].astype(int) > obs[..., 0].astype(int) + 40))[0]
        assert rows.size == 0 or rows.mean() > np.nonzero(g > r + 40)[0].mean() + 2
    finally:
        env.close()


def test_a_height_field_is_a_located_error(tmp_path: Path) -> None:
    (tmp_path / "h.xml").write_text(
        textwrap.dedent("""\
        <mujoco>
          <asset><hfield name="ground" nrow="4" ncol="4" size="1 1 0.1 0.1"/></asset>
          <worldbody><geom name="terrain" type="hfield" hfield="ground"/><camera name="c" pos="0 -2 1"/></worldbody>
        </mujoco>
        """),
        encoding="utf-8",
    )
    spec = tmp_path / "s.yaml"
    spec.write_text(
        "id: H-v0\nphysics: {model: h.xml}\nobservation: {camera: c}\nactions: {discrete: [{}]}\n", encoding="utf-8"
    )
    with pytest.raises(
        SpecError,
        match=r"s.yaml:2.*physics.model: geom 'terrain' is a height field \(hfield\), which visualenv cannot draw yet",
    ):
        VisualEnv(spec)


def brown_mask(image: np.ndarray) -> np.ndarray:
    pixels = image.astype(int)
    return pixels[..., 0] > pixels[..., 2] + 15


def brown(image: np.ndarray) -> int:
    return int(brown_mask(image).sum())


def test_half_cheetahs_track_camera_follows_it() -> None:
    env = visualenv.make("visualenv/VisualHalfCheetah-v0", samples=1)
    try:
        first, _ = env.reset(seed=0)
        env.unwrapped.data.qpos[0] += (
            5.0  # five metres on: a camera fixed in the world would see no cheetah (tested: 0 pixels)
        )
        obs, *_ = env.step(np.zeros(6))
        assert env.unwrapped.data.qpos[0] > 4.5
        before, after = (
            brown(first),
            brown(obs),
        )  # the cheetah's material (rgba .7 .5 .3) against the grey sky and light floor
        assert before > 50 and abs(after - before) < 0.3 * before, (before, after)
        col_before, col_after = (np.nonzero(brown_mask(image))[1].mean() for image in (first, obs))
        assert abs(col_after - col_before) < 5, (
            col_before,
            col_after,
        )  # where it was in the frame (the checker floor slid by)
    finally:
        env.close()


def test_a_planes_builtin_checker_texture_is_drawn(tmp_path: Path) -> None:
    (tmp_path / "c.xml").write_text(
        textwrap.dedent("""\
        <mujoco>
          <asset>
            <texture name="grid" type="2d" builtin="checker" rgb1="1 1 1" rgb2="0 0 0" width="64" height="64"/>
            <material name="grid" texture="grid" texrepeat="4 4"/>
          </asset>
          <worldbody>
            <light directional="true" pos="0 0 3" dir="0 0 -1"/>
            <geom name="floor" type="plane" size="1 1 0.1" material="grid"/>
            <camera name="top" pos="0 0 1.5"/>
          </worldbody>
        </mujoco>
        """),
        encoding="utf-8",
    )
    spec = tmp_path / "s.yaml"
    spec.write_text(
        "id: C-v0\nphysics: {model: c.xml}\nobservation: {camera: top, resolution: [32, 32], color: grayscale}\n"
        "actions: {discrete: [{}]}\n",
        encoding="utf-8",
    )
    gray = first_frame(spec)[..., 0]
    bright, dark = (gray > 150).mean(), (gray < 90).mean()
    assert bright > 0.2 and dark > 0.2, (
        bright,
        dark,
        gray[16],
    )  # squares of both colours, not the plain grey of a material without texture
    # 4 repeats of a 2x2 checker across the plane: the colour flips along a row several times
    flips = int(np.count_nonzero(np.diff(gray[16] > 120)))
    assert flips >= 4, gray[16]


def test_a_spec_binds_a_geoms_colour(tmp_path: Path) -> None:
    """actors reach the model's geoms by name: a colour drawn at reset recolours the pole (domain randomisation)."""
    path = tmp_path / "pole.yaml"
    path.write_text(
        POLE + "state:\n  red: {init: 'uniform(0.8, 1.0)'}\nactors:\n  cpole: {color: [red, 0, 0]}\n", encoding="utf-8"
    )
    env = visualenv.make(path)
    try:
        obs, _ = env.reset(seed=0)
        r, g, b = (obs[..., i].astype(int) for i in range(3))
        assert cyan(obs).sum() == 0 and ((r > g + 40) & (r > b + 40)).sum() >= 8
    finally:
        env.close()


def test_a_light_on_a_body_moves_with_it(tmp_path: Path) -> None:
    """A light inside a falling body takes MuJoCo's light_xpos each step (a light on a body, or tracking one, moves)."""
    (tmp_path / "l.xml").write_text(
        textwrap.dedent("""\
        <mujoco>
          <worldbody>
            <geom name="floor" type="plane" size="2 2 0.1" rgba="0.8 0.8 0.8 1"/>
            <body name="lamp" pos="0 0 2">
              <freejoint/>
              <geom type="sphere" size="0.05" contype="0" conaffinity="0"/>
              <light name="bulb" pos="0 0 0" dir="0 0 -1" cutoff="60"/>
            </body>
            <camera name="side" pos="0 -4 1" xyaxes="1 0 0 0 0.2 1"/>
          </worldbody>
        </mujoco>
        """),
        encoding="utf-8",
    )
    spec = tmp_path / "s.yaml"
    spec.write_text(
        "id: L-v0\nphysics: {model: l.xml, frame_skip: 10}\nobservation: {camera: side, resolution: [16, 16]}\n"
        "actions: {discrete: [{}]}\n",
        encoding="utf-8",
    )
    env = VisualEnv(spec)
    try:
        env.reset(seed=0)
        light = env.renderer.object("bulb")
        assert abs(light.location[2] - 2.0) < 1e-6
        for _ in range(20):
            env.step(0)
        z = env.unwrapped.data.light_xpos[0][2]
        assert z < 1.5 and abs(light.location[2] - z) < 1e-6, (z, tuple(light.location))
    finally:
        env.close()


def test_a_batch_renders_each_envs_own_pose(tmp_path: Path) -> None:
    """Copy i of a rendered batch takes lane i's MuJoCo poses: tile i equals env i rendered alone (a moving model camera: tests/env/test_batch_tracking.py)."""
    from visualenv.env.batch import BatchedVectorEnv

    path = tmp_path / "pole.yaml"
    path.write_text(
        POLE.replace("values: {qpos_hinge: angle}", "values: {qpos_hinge: 'uniform(-1, 1)'}"), encoding="utf-8"
    )
    batch = BatchedVectorEnv(path, 3)
    singles = [VisualEnv(path) for _ in range(3)]
    try:
        obs, _ = batch.reset(seed=2)
        renderer = (
            batch.renderer
        )  # the model's bodies are instances, posed from every env's poses at once: nothing per copy
        assert renderer._instances.posed and renderer._copy_poses == []
        for i, env in enumerate(singles):
            alone, _ = env.reset(seed=2 + i)
            assert batch.lanes[i].data.qpos[1] == env.data.qpos[1]
            close = (np.abs(obs[i].astype(int) - alone.astype(int)) <= 8).mean()
            assert close >= 0.98, (i, close)
        # the three poles lean differently: the tiles differ where the poles are
        assert (cyan(obs[0]) != cyan(obs[1])).sum() + (cyan(obs[1]) != cyan(obs[2])).sum() > 4
        # the poses handed are the ones drawn, also where the list handed before now holds other arrays
        poses = batch._pose_arrays
        poses[:] = [tuple(np.array(a, copy=True) for a in poses[j]) for j in (2, 0, 1)]
        renderer.render(Frames(batch.binding_table(), poses))
        assert not np.array_equal(poses[0][1], poses[1][1])  # env 2's pole leans otherwise than env 0's
        assert all(np.array_equal(renderer._body_poses[part][i], poses[i][part]) for i in range(3) for part in (0, 1))
    finally:
        batch.close()
        for env in singles:
            env.close()


ARM = """\
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1" rgba="0.8 0.8 0.8 1"/>
    <body name="arm" pos="0 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0"/>
      <geom name="rod" type="capsule" fromto="0 0 0 0.6 0 0" size="0.05" rgba="0 0.7 0.7 1"/>
      <body name="tip" pos="0.6 0 0">
        <joint name="wrist" type="hinge" axis="0 1 0"/>
        <geom name="ball" type="sphere" size="0.12" rgba="1 1 0 1"/>
      </body>
    </body>
    <body name="lamp" pos="0.3 -0.6 2">
      <freejoint/>
      <geom name="glass" type="sphere" size="0.05" rgba="1 1 1 1"/>
      <light name="bulb" pos="0 0 0" dir="0 0 -1" cutoff="60"/>
    </body>
  </worldbody>
</mujoco>
"""
BULB = '      <light name="bulb" pos="0 0 0" dir="0 0 -1" cutoff="60"/>\n'


def test_a_batch_draws_the_models_bodies_as_instances_with_the_pixels_of_copies(tmp_path: Path) -> None:
    """A rendered batch draws the model's bodies (nested, free, a bound colour) as Geometry Nodes instances posed from
    every env's xpos and xquat at once, under a directional light (a spot light per env keeps every object a copy:
    the next test). Tiles equal those of the copied objects (the path before) pixel for pixel, step after step."""
    from visualenv.env.batch import BatchedVectorEnv
    from visualenv.render.base import RendererOptions
    from visualenv.render.blender.batch.renderer import BatchedBlenderRenderer

    (tmp_path / "arm.xml").write_text(
        ARM.replace(BULB, "").replace(
            "<worldbody>", '<worldbody>\n    <light directional="true" pos="0 0 3" dir="0 0.3 -1"/>'
        ),
        encoding="utf-8",
    )
    path = tmp_path / "arm.yaml"
    path.write_text(
        textwrap.dedent("""\
        id: Arm-v0
        physics: {model: arm.xml, frame_skip: 50, reset: {values: {qpos_hinge: 'uniform(-1, 1)', qpos_wrist: 'uniform(-1, 1)'}}}
        scene:
          world: {color: [0.1, 0.1, 0.12]}
          objects:
            Camera: {camera: perspective, location: [0.3, -2.2, 1.2], look_at: [0.3, 0, 0.9], lens: 30}
        state: {red: {init: 'uniform(0.5, 1.0)'}}
        actors: {ball: {color: [red, red, 0]}}
        observation: {camera: Camera, resolution: [24, 24], color: rgb}
        actions: {discrete: [{}]}
        reward: 0.0
        """),
        encoding="utf-8",
    )
    batch = BatchedVectorEnv(path, 3)
    options = RendererOptions.parse(None)
    copies = BatchedBlenderRenderer(
        batch.program.render_plan().with_options(options), options, num_envs=3, instanced=False
    )
    try:
        obs, _ = batch.reset(seed=4)
        renderer = batch.renderer
        instanced = {
            name
            for name in ("body:arm", "body:tip", "body:lamp", "rod", "ball", "glass")
            if renderer.object(name).as_pointer() in renderer._removed
        }
        assert instanced == {"body:arm", "body:tip", "body:lamp", "rod", "ball", "glass"}, instanced
        assert not any(w.bodies for _, w in renderer._copy_poses or [])  # no body of any copy is posed from Python
        frames = []
        for step in range(3):
            theirs = copies.render(Frames(batch.binding_table(), batch._pose_arrays))
            assert np.array_equal(obs, theirs), f"step {step}: {(obs != theirs).any(axis=-1).sum()} pixels differ"
            frames.append(obs.copy())
            obs, *_ = batch.step(np.zeros(3, dtype=np.int64))
        # a test that cannot fail otherwise: the envs' tiles differ, and the scene moves between steps (the lamp falls)
        assert not np.array_equal(frames[0][0], frames[0][1]) and not np.array_equal(frames[0][0], frames[2][0])
    finally:
        copies.close()
        batch.close()


def test_a_spot_light_on_a_falling_body_lights_only_its_own_env(tmp_path: Path) -> None:
    """A spot light per env (on a falling body): every object is a copy, posed copy by copy, and each copy's spot
    lights and shadows only its own copy (Cycles' light linking: tests/specs/test_dmc_render.py shows what sharing the spots
    did). Tiles equal each env rendered alone, so no object of a copy is left out of its light, and the bulb's light
    moves as its lamp falls."""
    from visualenv.env.batch import BatchedVectorEnv

    (tmp_path / "arm.xml").write_text(ARM, encoding="utf-8")
    path = tmp_path / "lamp.yaml"
    path.write_text(
        "id: Lamp-v0\nphysics: {model: arm.xml, frame_skip: 50, reset: {values: {qpos_hinge: 'uniform(-1, 1)'}}}\n"
        "scene: {objects: {Camera: {camera: perspective, location: [0.3, -2.2, 1.2], look_at: [0.3, 0, 0.9], lens: 30}}}\n"
        "observation: {camera: Camera, resolution: [24, 24], color: rgb}\nactions: {discrete: [{}]}\nreward: 0.0\n",
        encoding="utf-8",
    )
    n = 6
    batch = BatchedVectorEnv(path, n)
    singles = [VisualEnv(path) for _ in range(n)]
    try:
        obs, _ = batch.reset(seed=2)
        renderer = batch.renderer
        assert not renderer._removed  # no instances: light linking is per object
        assert [(k, len(w.bodies), len(w.lights)) for k, w in renderer._copy_poses] == [(k, 3, 1) for k in range(n)]
        bulbs = [copy.objects["bulb"] for copy in renderer._copies]
        for k, bulb in enumerate(bulbs):
            assert renderer._copies[k].objects["glass"] in set(bulb.light_linking.receiver_collection.objects), k
            assert bulb.light_linking.blocker_collection == bulb.light_linking.receiver_collection
        frames = []
        for step in range(2):
            for i, env in enumerate(singles):
                alone = env.reset(seed=2 + i)[0] if step == 0 else env.step(0)[0]
                difference = np.abs(obs[i].astype(int) - alone.astype(int))
                assert difference.mean() < 0.5 and (difference <= 8).mean() > 0.99, (step, i, difference.mean())
            frames.append(obs.copy())
            obs, *_ = batch.step(np.zeros(n, dtype=np.int64))
        assert not np.array_equal(frames[0][0], frames[1][0])  # the lamp fell: its light moved
    finally:
        batch.close()
        for env in singles:
            env.close()


def test_a_batch_sees_through_the_models_fixed_camera(tmp_path: Path) -> None:
    """A batch observing through a fixed camera of the model renders from that camera's pose (its tiles camera is built
    before any step, so the model's camera stands at its pose from the start): tile i is env i alone."""
    from visualenv.env.batch import BatchedVectorEnv

    lamp = ARM[
        ARM.index('    <body name="lamp"') : ARM.index("  </worldbody>")
    ]  # a spot light per copy: more lights to sample, other noise
    (tmp_path / "arm.xml").write_text(
        ARM.replace(
            lamp,
            '    <light directional="true" pos="0 0 3" dir="0 0.3 -1"/>\n'
            '    <camera name="side" pos="0.3 -2.2 1.1" xyaxes="1 0 0 0 0.1 1"/>\n',
        ),
        encoding="utf-8",
    )
    path = tmp_path / "side.yaml"
    path.write_text(
        "id: Side-v0\nphysics: {model: arm.xml, reset: {values: {qpos_hinge: 'uniform(-1, 1)'}}}\n"
        "observation: {camera: side, resolution: [16, 16], color: rgb}\nactions: {discrete: [{}]}\nreward: 0.0\n",
        encoding="utf-8",
    )
    batch = BatchedVectorEnv(path, 2)
    singles = [VisualEnv(path) for _ in range(2)]
    try:
        obs, _ = batch.reset(seed=6)
        for i, env in enumerate(singles):
            alone, _ = env.reset(seed=6 + i)
            close = (
                np.abs(obs[i].astype(int) - alone.astype(int)) <= 8
            ).mean()  # as the batch test above (the world at the origin: 0.67)
            assert close >= 0.98, (i, close)
        assert not np.array_equal(obs[0], obs[1])  # the arms swing differently: each tile shows its own env
    finally:
        batch.close()
        for env in singles:
            env.close()


def test_a_mesh_geom_is_drawn_as_mujoco_compiled_it(tmp_path: Path) -> None:
    """An MJCF mesh (inline vertices, no file) is drawn from MuJoCo's compiled vertices and faces: a yellow tetrahedron left of a box."""
    (tmp_path / "m.xml").write_text(
        textwrap.dedent("""\
        <mujoco>
          <asset><mesh name="tet" vertex="0 0 0  0.6 0 0  0 0.6 0  0 0 0.6"/></asset>
          <worldbody>
            <light directional="true" pos="0 -2 3" dir="0 1 -1"/>
            <body name="thing" pos="-0.4 0 0"><freejoint/><geom name="tet" type="mesh" mesh="tet" rgba="1 1 0 1"/></body>
            <camera name="front" pos="0 -3 0.3" xyaxes="1 0 0 0 0 1"/>
          </worldbody>
          <option gravity="0 0 0"/>
        </mujoco>
        """),
        encoding="utf-8",
    )
    spec = tmp_path / "s.yaml"
    spec.write_text(
        "id: M-v0\nphysics: {model: m.xml}\nscene: {world: {color: [0, 0, 0]}}\n"
        "observation: {camera: front, resolution: [24, 24], color: rgb}\nactions: {discrete: [{}]}\n",
        encoding="utf-8",
    )
    r, g, b = (first_frame(spec)[..., i] for i in range(3))
    yellow = (r > b + 40) & (g > b + 40)
    cols = np.nonzero(yellow)[1]
    assert yellow.sum() >= 6 and cols.mean() < 12, (yellow.sum(), cols)


def test_an_object_named_as_a_body_stands_for_it(tmp_path: Path) -> None:
    """A spec object called 'pole' (a red cylinder) replaces the pole body's geoms and takes its pose: it leans with the hinge."""
    own = POLE.replace(
        "    Camera:",
        "    pole: {primitive: cylinder, radius: 0.06, depth: 0.6, origin: bottom, material: {color: [1, 0, 0]}}\n    Camera:",
    )
    path = tmp_path / "own.yaml"
    path.write_text(own, encoding="utf-8")
    centres = []
    for angle in (0.0, 1.0):
        env = visualenv.make(path, params={"angle": angle})
        try:
            obs, _ = env.reset(seed=0)
        finally:
            env.close()
        r, g, b = (obs[..., i].astype(int) for i in range(3))
        red = (r > g + 40) & (r > b + 40)
        assert cyan(obs).sum() == 0 and red.sum() >= 6, (
            cyan(obs).sum(),
            red.sum(),
        )  # the capsule is not drawn; the cylinder is
        centres.append(np.nonzero(red)[1].mean())
    assert centres[1] > centres[0] + 4, centres


#: POLE with the cart slid to `start` at reset, seen by a camera that looks along +y without aiming at the pole
FOLLOWING = (
    POLE.replace("Pole-v0", "Follow-v0")
    .replace("{angle: 0.0}", "{start: 0.0}")
    .replace("qpos_hinge: angle", "qpos_slider: start")
    .replace("look_at: [0, 0, 0.3]", "rotation: [1.5708, 0, 0]")
)
assert FOLLOWING.count("start") == 2 and "rotation" in FOLLOWING


def pole_column(tmp_path: Path, text: str, start: float) -> float:
    """The mean column of the pole's pixels with the cart slid to `start` at reset."""
    path = tmp_path / "follow.yaml"
    path.write_text(text, encoding="utf-8")
    env = visualenv.make(path, params={"start": start})
    try:
        obs, _ = env.reset(seed=0)
        pole = np.argwhere(cyan(obs))
        assert len(pole) >= 8
        return float(pole[:, 1].mean())
    finally:
        env.close()


def test_an_actor_binding_reads_the_models_names_so_a_camera_follows_the_cart(tmp_path: Path) -> None:
    """`actors: {Camera: {location: [qpos_slider, ...]}}`: the pole stays in the middle of the frame wherever the cart is."""
    following = FOLLOWING + "actors: {Camera: {location: [qpos_slider, -3, 0.3]}}\n"
    assert abs(pole_column(tmp_path, following, 0.6) - pole_column(tmp_path, following, 0.0)) < 1.0
    assert (
        pole_column(tmp_path, FOLLOWING, 0.6) - pole_column(tmp_path, FOLLOWING, 0.0) > 4.0
    )  # a fixed camera sees it move right


TEXTURED = """\
<mujoco>
  <asset>
    <texture name="cube" type="cube" builtin="checker" rgb1="1 0 0" rgb2="0 0 1" width="16" height="16"/>
    <texture name="flat" type="2d" builtin="checker" rgb1="1 1 0" rgb2="0 0.8 0" width="16" height="16"/>
    <texture name="quads" type="2d" file="quads.png"/>
    <material name="cube" texture="cube"/>
    <material name="flat" texture="flat"/>
    <material name="quads" texture="quads"/>
    <mesh name="cube" vertex="-.2 -.2 -.2  .2 -.2 -.2  .2 .2 -.2  -.2 .2 -.2  -.2 -.2 .2  .2 -.2 .2  .2 .2 .2  -.2 .2 .2"/>
    <mesh name="pyramid" file="pyramid.obj"/>
  </asset>
  <worldbody>
    <light directional="true" pos="0 -3 1" dir="0 1 -0.2"/>
    <geom name="box" type="box" size="0.2 0.2 0.2" pos="-0.9 0 0.45" material="cube"/>
    <geom name="ellipsoid" type="ellipsoid" size="0.15 0.15 0.22" pos="-0.3 0 0.45" material="cube"/>
    <geom name="capsule" type="capsule" size="0.12 0.12" pos="0.3 0 0.45" material="cube"/>
    <geom name="cylinder" type="cylinder" size="0.18 0.2" pos="0.9 0 0.45" material="cube"/>
    <geom name="sphere" type="sphere" size="0.22" pos="-0.9 0 -0.45" material="flat"/>
    <geom name="mesh" type="mesh" mesh="cube" pos="-0.3 0 -0.45" material="cube"/>
    <geom name="picture" type="box" size="0.2 0.2 0.2" pos="0.3 0 -0.45" euler="90 0 0" material="quads"/>
    <geom name="uv" type="mesh" mesh="pyramid" pos="0.9 0 -0.45" material="quads"/>
    <camera name="front" pos="0 -3.2 0" xyaxes="1 0 0 0 0 1"/>
  </worldbody>
</mujoco>
"""

#: a square pyramid whose base faces the camera (-y), with texture coordinates that put the whole image on the base
PYRAMID = """\
v -0.2 0 -0.2
v 0.2 0 -0.2
v 0.2 0 0.2
v -0.2 0 0.2
v 0 0.2 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vt 0.5 0.5
f 1/1 2/2 3/3
f 1/1 3/3 4/4
f 1/1 5/5 2/2
f 2/2 5/5 3/3
f 3/3 5/5 4/4
f 4/4 5/5 1/1
"""


def test_textures_are_drawn_on_every_geom_type_as_mujoco_maps_them(tmp_path: Path) -> None:
    """Cube, builtin 2-D and image textures on boxes, ellipsoids, capsules, cylinders, spheres and meshes (64x64).

    MuJoCo's mapping, read in its pixels: a builtin cube checker shows each face of
    a box (or a cube mesh) as 2x2 squares, red at top left on the face toward the
    camera (-Y: OpenGL's cube map face with s = x, t = -z); a 2-D texture projects
    along the geom's z axis, so a box turned to face the camera with its +z shows
    the image upright (its top row at the box's +y); a mesh with its own texture
    coordinates (an OBJ's) shows the image as they place it.
    """
    from PIL import Image

    quads = np.zeros((4, 4, 3), np.uint8)
    quads[:2, :2], quads[:2, 2:], quads[2:, :2], quads[2:, 2:] = (
        (255, 0, 255),
        (0, 255, 255),
        (255, 255, 0),
        (255, 255, 255),
    )
    Image.fromarray(quads).save(tmp_path / "quads.png")
    (tmp_path / "m.xml").write_text(TEXTURED, encoding="utf-8")
    (tmp_path / "pyramid.obj").write_text(PYRAMID, encoding="utf-8")
    spec = tmp_path / "s.yaml"
    spec.write_text(
        "id: T-v0\nphysics: {model: m.xml}\nscene: {world: {color: [0.5, 0.5, 0.5]}}\n"
        "observation: {camera: front, resolution: [64, 64], color: rgb}\nactions: {discrete: [{}]}\n",
        encoding="utf-8",
    )
    r, g, b = (first_frame(spec)[..., i] for i in range(3))
    colours = {
        "red": (r > g + 60) & (r > b + 60),
        "blue": (b > r + 60) & (b > g + 60),
        "yellow": (r > b + 60) & (g > b + 60),
        "green": (g > r + 60) & (g > b + 60),
        "magenta": (r > g + 60) & (b > g + 60),
        "cyan": (g > r + 60) & (b > r + 60),
        "white": (r > 200) & (g > 200) & (b > 200),
    }
    scale = (
        32 / np.tan(np.radians(22.5)) / 3.2
    )  # pixels per metre at the geoms' depth (MuJoCo's default fovy, 45 degrees)

    def centre(x: float, z: float) -> tuple[float, float]:
        return 32 + x * scale, 32 - z * scale

    def quadrant(x: float, z: float, dx: float, dz: float) -> str:
        col, row = centre(x, z)
        col, row = int(col + dx * 2.5), int(row - dz * 2.5)
        block = {name: int(mask[row - 1 : row + 1, col - 1 : col + 1].sum()) for name, mask in colours.items()}
        return max(block, key=lambda k: block[k])

    for name, x, z in (
        ("box", -0.9, 0.45),
        ("mesh", -0.3, -0.45),
    ):  # (left/right, down/up) quadrants of the face toward the camera
        seen = [quadrant(x, z, dx, dz) for dz in (1, -1) for dx in (-1, 1)]
        assert seen == ["red", "blue", "blue", "red"], (name, seen)
    for x in (0.3, 0.9):  # the turned box's 2-D projection, the mesh's own UVs: the image upright
        assert [quadrant(x, -0.45, dx, dz) for dz in (1, -1) for dx in (-1, 1)] == [
            "magenta",
            "cyan",
            "yellow",
            "white",
        ], x
    for name, x, z, pair in (
        ("ellipsoid", -0.3, 0.45, ("red", "blue")),
        ("capsule", 0.3, 0.45, ("red", "blue")),
        ("cylinder", 0.9, 0.45, ("red", "blue")),
        ("sphere", -0.9, -0.45, ("yellow", "green")),
    ):
        col, row = (int(v) for v in centre(x, z))
        window = (slice(row - 4, row + 5), slice(col - 4, col + 5))
        counts = [int(colours[c][window].sum()) for c in pair]
        assert min(counts) >= 4, (name, counts)  # both of the texture's colours, not one flat colour


SKYBOX = """\
<mujoco>
  <asset>{sky}</asset>
  <worldbody>
    <light directional="true" pos="0 -2 3" dir="0 0.5 -1"/>
    <geom name="block" type="box" size="0.5 0.5 0.5" rgba="0.8 0.3 0.2 1"/>
    <camera name="level" pos="0 -3 0" xyaxes="1 0 0 0 0 1"/>
  </worldbody>
</mujoco>
"""


def skybox_frame(tmp_path: Path, *, sky: bool, world: str = "") -> np.ndarray:
    (tmp_path / "m.xml").write_text(
        SKYBOX.format(
            sky='<texture type="skybox" builtin="gradient" rgb1="1 1 1" rgb2="0 0 0" width="32" height="32"/>'
            if sky
            else ""
        ),
        encoding="utf-8",
    )
    spec = tmp_path / "s.yaml"
    spec.write_text(
        f"id: Sky-v0\nphysics: {{model: m.xml}}\n{world}observation: {{camera: level, resolution: [24, 24], color: rgb}}\n"
        "actions: {discrete: [{}]}\n",
        encoding="utf-8",
    )
    return first_frame(spec)


def test_the_models_skybox_shows_behind_it_and_lights_nothing(tmp_path: Path) -> None:
    """MuJoCo draws a skybox behind the model, unlit and lighting nothing: rgb1 above the horizon, rgb2 below.
    A batch shows it behind every tile; a world the spec declares replaces it."""
    with_sky, without = skybox_frame(tmp_path, sky=True), skybox_frame(tmp_path, sky=False)
    rows = with_sky.mean(axis=(1, 2))
    assert rows[:3].mean() > rows[-3:].mean() + 60, rows  # the camera looks level: brighter above than below
    assert np.ptp(without.mean(axis=(1, 2))[[0, 1, 2, -3, -2, -1]]) < 5  # without a skybox: the plain default world
    block = (without[..., 0] > without[..., 2] + 40) & (with_sky[..., 0] > with_sky[..., 2] + 40)
    inner = block[1:-1, 1:-1] & block[:-2, 1:-1] & block[2:, 1:-1] & block[1:-1, :-2] & block[1:-1, 2:]  # off the edges
    assert inner.sum() >= 30, inner.sum()
    diff = np.abs(with_sky[1:-1, 1:-1][inner] - without[1:-1, 1:-1][inner])
    assert diff.max() <= 1, diff.max()  # the block lit as without the skybox (the same pixels, measured)
    from visualenv.env.batch import BatchedVectorEnv

    skybox_frame(tmp_path, sky=True)  # the files again, with the skybox
    batch = BatchedVectorEnv(tmp_path / "s.yaml", 2)
    try:
        tiles = batch.reset(seed=0)[0].astype(int)
    finally:
        batch.close()
    assert np.abs(tiles - with_sky[None]).max() <= 8  # each tile of a batch: the sky behind it as in one env
    declared = skybox_frame(tmp_path, sky=True, world="scene: {world: {color: [0.2, 0.2, 0.2]}}\n")
    corners = declared[[0, 0, -1, -1], [0, -1, 0, -1]]
    assert np.ptp(corners) < 5, corners  # the spec's world wins: one colour above and below
