"""Sites drawn as MuJoCo's viewer draws them: groups 0 to 2, their type, size and rgba; ``physics.draw_sites: false`` leaves them out.

A model written here marks a target with a red site (no geom there): the agent
sees it, in one env and in a batch's tiles, as MuJoCo's renderer shows it; a site of
group 3 and a transparent one stay hidden; a site on a body moves with it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from visualenv.compiler.program import compile_spec  # noqa: E402
from visualenv.env.batch import BatchedVectorEnv  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.spec.loader import load_spec  # noqa: E402

MODEL = """\
<mujoco>
  <worldbody>
    <light directional="true" pos="0 0 3" dir="0 0 -1"/>
    <geom name="floor" type="plane" size="2 2 0.1" rgba="0.3 0.3 0.3 1"/>
    <body name="ball" pos="-0.5 0 0.3">
      <freejoint name="ball"/>
      <geom name="ball_geom" type="sphere" size="0.1" rgba="0 0 1 1"/>
      <site name="marker" type="box" size="0.06 0.06 0.06" pos="0 0 0.12" rgba="0 1 0 1"/>
    </body>
    <site name="target" type="sphere" size="0.15" pos="0.5 0 0.05" rgba="1 0 0 1"/>
    <site name="hidden" type="sphere" size="0.15" pos="0 0.5 0.05" rgba="1 0 0 1" group="3"/>
    <site name="clear" type="sphere" size="0.15" pos="0 -0.5 0.05" rgba="1 0 0 0"/>
    <site name="post" type="cylinder" size="0.05 0.2" pos="0.5 0.6 0.2" rgba="1 1 0 1"/>
    <site name="bar" type="capsule" size="0.03 0.1" pos="0.5 -0.6 0.2" rgba="1 0 1 1"/>
    <site name="egg" type="ellipsoid" size="0.1 0.05 0.05" pos="-0.5 -0.6 0.05" rgba="0 1 1 1"/>
    <site name="default"/>
    <camera name="top" pos="0 0 3"/>
  </worldbody>
</mujoco>
"""

SPEC = """\
id: Sites-v0
params: {bx: -0.5}
physics: {model: sites.xml, reset: {values: {qpos_ball_x: bx}}}
actions: {discrete: [{}]}
reward: 0
scene: {world: {color: [0, 0, 0]}}
observation: {camera: top, resolution: [32, 32], color: rgb}
render: {noise: shared}   # Cycles' noise as a batch renders it: a tile equals the env rendered alone
"""


def write(tmp_path: Path, spec: str = SPEC) -> Path:
    (tmp_path / "sites.xml").write_text(MODEL, encoding="utf-8")
    path = tmp_path / "sites.yaml"
    path.write_text(spec, encoding="utf-8")
    return path


def test_the_scene_holds_the_visible_sites_with_their_shapes(tmp_path: Path) -> None:
    scene = compile_spec(load_spec(write(tmp_path))).physics.scene
    sites = {s.name: s for s in scene.sites}
    assert set(sites) == {
        "site:marker",
        "site:target",
        "site:post",
        "site:bar",
        "site:egg",
        "site:default",
    }  # not hidden, not clear
    assert (sites["site:target"].kind, sites["site:target"].size[0], sites["site:target"].rgba) == (
        "sphere",
        0.15,
        (1.0, 0.0, 0.0, 1.0),
    )
    assert [sites[n].kind for n in ("site:marker", "site:post", "site:bar", "site:egg")] == [
        "box",
        "cylinder",
        "capsule",
        "ellipsoid",
    ]
    assert sites["site:marker"].body == 1 and sites["site:marker"].pos == (0.0, 0.0, 0.12)  # in its body's frame
    assert sites["site:default"].size[0] == 0.005 and sites["site:default"].rgba == (
        0.5,
        0.5,
        0.5,
        1.0,
    )  # MuJoCo's defaults
    off = compile_spec(
        load_spec(
            write(
                tmp_path, SPEC.replace("physics: {model: sites.xml,", "physics: {model: sites.xml, draw_sites: false,")
            )
        )
    )
    assert off.physics.scene.sites == ()


def test_inspect_lists_the_sites_it_draws(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from visualenv.cli import main

    write(tmp_path)
    result = CliRunner().invoke(main, ["inspect", str(tmp_path / "sites.xml")])
    assert result.exit_code == 0, result.output
    line = next(t for t in result.output.splitlines() if t.startswith("drawn sites"))
    assert "target (sphere)" in line and "post (cylinder)" in line and "hidden" not in line and "clear" not in line, (
        line
    )


def red(image: np.ndarray) -> np.ndarray:
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (r > 80) & (r > g + 50) & (r > b + 50)


def green(image: np.ndarray) -> np.ndarray:
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (g > 80) & (g > r + 50) & (g > b + 50)


@pytest.mark.blender
def test_a_red_site_in_view_shows_red_pixels_alone_and_in_a_batch_and_draw_sites_false_hides_it(tmp_path: Path) -> None:
    """The target site (red, +x of the centre) is the only red in the picture: group 3 and transparent sites stay hidden.
    The marker site rides on the ball. A batch's tiles show the same; draw_sites: false shows no site at all."""
    path = write(tmp_path)
    env = VisualEnv(path)
    batch = BatchedVectorEnv(path, 2)
    try:
        obs, _ = env.reset(seed=0)
        rows, cols = np.nonzero(red(obs))
        assert (
            rows.size >= 6 and cols.min() > 16
        )  # only the target's red, right of the centre: the other two red sites hidden
        assert abs(cols.mean() - (15.5 + 0.5 * 32 / 2.485)) < 1.5 and abs(rows.mean() - 15.5) < 1.5, (
            rows.mean(),
            cols.mean(),
        )
        marker = np.nonzero(green(obs))
        assert marker[0].size >= 2 and marker[1].mean() < 12  # on the ball, left of the centre
        tiles, _ = batch.reset(seed=0)
        for tile in tiles:
            assert (np.abs(tile.astype(int) - obs.astype(int)) <= 8).mean() >= 0.99
    finally:
        batch.close()
        env.close()
    moved = VisualEnv(path, params={"bx": 0.0})  # the ball half a metre to the right: its marker with it
    try:
        obs, _ = moved.reset(seed=0)
        metres = (
            2 * (3 - 0.42) * np.tan(np.radians(22.5))
        )  # what 32 px span at the marker's height (MuJoCo's 45 degree fovy)
        assert abs(np.nonzero(green(obs))[1].mean() - marker[1].mean() - 0.5 * 32 / metres) < 1.5
    finally:
        moved.close()
    hidden = VisualEnv(
        write(tmp_path, SPEC.replace("physics: {model: sites.xml,", "physics: {model: sites.xml, draw_sites: false,"))
    )
    try:
        obs, _ = hidden.reset(seed=0)
        assert not red(obs).any() and not green(obs).any()
    finally:
        hidden.close()
