"""Tendons drawn as MuJoCo draws them: the path's points equal the capsules MuJoCo's own scene (mjv_updateScene, which
needs no OpenGL) holds for the tendon, a slack string hanging as a catenary and a taut one straight."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "disable")
mujoco = pytest.importorskip("mujoco")

from visualenv.physics.model import load_model  # noqa: E402
from visualenv.physics.scene import visible_tendons  # noqa: E402
from visualenv.physics.tendons import tendon_path  # noqa: E402

ASSETS = Path(__file__).resolve().parents[2] / "specs" / "dmc" / "assets"

#: a string through three sites: MuJoCo draws it straight (only a two-site string hangs)
THREE_SITES = """<mujoco><worldbody>
  <site name="a" pos="0 0 1"/><site name="b" pos=".2 0 .5"/>
  <body name="weight" pos=".4 0 .2"><joint type="slide" axis="0 0 1"/><geom size=".05"/><site name="c"/></body>
</worldbody><tendon><spatial width=".01" limited="true" range="0 2"><site site="a"/><site site="b"/><site site="c"/>
</spatial></tendon></mujoco>"""


def mujocos_tendon_points(model, data) -> np.ndarray:
    """The points MuJoCo's scene draws the tendon's capsules between, in order."""
    scene = mujoco.MjvScene(model, maxgeom=1000)
    mujoco.mjv_updateScene(
        model, data, mujoco.MjvOption(), mujoco.MjvPerturb(), mujoco.MjvCamera(), mujoco.mjtCatBit.mjCAT_ALL, scene
    )
    ends = []
    for k in range(scene.ngeom):
        geom = scene.geoms[k]
        if geom.objtype == mujoco.mjtObj.mjOBJ_TENDON:
            centre, axis = np.array(geom.pos, float), np.array(geom.mat, float).reshape(3, 3)[:, 2]
            ends.append((centre - axis * geom.size[2], centre + axis * geom.size[2]))
    return np.array([ends[0][0]] + [end for _, end in ends])


def sites_of(model, data, tendon: int) -> np.ndarray:
    first = int(model.tendon_adr[tendon])
    return np.array(
        [data.site_xpos[int(model.wrap_objid[w])] for w in range(first, first + int(model.tendon_num[tendon]))]
    )


def test_ball_in_cups_string_hangs_and_pulls_straight_as_mujoco_draws_it() -> None:
    physics = load_model(ASSETS / "ball_in_cup.xml")
    model, data = physics.model, mujoco.MjData(physics.model)
    (string,) = visible_tendons(physics)
    assert string.hanging == 0.3 and string.slices == 29 and string.segments == 28
    rng = np.random.default_rng(0)
    shapes = set()
    for _ in range(100):
        data.qpos[:] = rng.uniform(-0.4, 0.4, model.nq)
        mujoco.mj_forward(model, data)
        theirs = mujocos_tendon_points(model, data)
        ours = tendon_path(string, sites_of(model, data, 0))
        shapes.add(len(ours))
        assert ours.shape == theirs.shape
        np.testing.assert_allclose(ours, theirs, atol=1e-6)  # MuJoCo's scene keeps float32
    assert shapes == {2, 29}, "both a taut string and a hanging one were drawn"


def test_a_string_through_three_sites_is_drawn_straight(tmp_path: Path) -> None:
    (tmp_path / "three.xml").write_text(THREE_SITES)
    physics = load_model(tmp_path / "three.xml")
    model, data = physics.model, mujoco.MjData(physics.model)
    mujoco.mj_forward(model, data)
    (tendon,) = visible_tendons(physics)
    assert tendon.hanging is None and tendon.segments == 2
    np.testing.assert_allclose(
        tendon_path(tendon, sites_of(model, data, 0)), mujocos_tendon_points(model, data), atol=1e-6
    )
