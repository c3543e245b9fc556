"""MuJoCo's version gates (visualenv/compat/mujoco.py), checked on the installed MuJoCo: each gate's field or call is
there and reads as the gate expects, the older route still answers, and MuJoCo moving makes this fail."""

from __future__ import annotations

import sys
from types import SimpleNamespace

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")
from visualenv.compat import mujoco as compat  # noqa: E402

MODEL = """
<mujoco>
  <asset><texture name="flat" type="2d" builtin="flat" rgb1="1 0 0" width="4" height="4"/></asset>
  <worldbody>
    <light name="sun" type="directional"/><light name="lamp" type="spot" pos="0 0 2"/>
    <body><joint name="hinge" type="hinge"/><geom size="0.1" mass="1"/></body>
  </worldbody>
  <actuator>
    <motor joint="hinge" ctrllimited="true" ctrlrange="-1 1"/><motor joint="hinge" ctrllimited="false"/>
  </actuator>
</mujoco>
"""


@pytest.fixture(scope="module")
def spec():
    return mujoco.MjSpec.from_string(MODEL)


def test_mujoco_is_a_version_the_gates_were_checked_against():
    """Fails when MuJoCo moves: read its changelog for light_type, tex_nchannel, actuator_ctrllimited, MjSpec.delete and
    mujoco.batch, then add its version to CHECKED."""
    assert compat.checked(), f"mujoco {mujoco.__version__} is not in compat/mujoco.py's CHECKED {compat.CHECKED}"


def test_a_light_is_directional_by_its_type_and_by_the_older_flag(spec):
    model = spec.compile()
    assert hasattr(model, "light_type"), "MuJoCo dropped light_type: read how it tells a directional light now"
    assert compat.LIGHT_DIRECTIONAL == int(mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    assert [compat.light_directional(model, i) for i in range(model.nlight)] == [True, False]
    older = SimpleNamespace(light_directional=np.array([0, 1], np.uint8))  # MuJoCo 3.2.0 to 3.3.2
    assert [compat.light_directional(older, i) for i in range(2)] == [False, True]


def test_a_texture_has_its_channels_and_the_older_ones_are_rgb(spec):
    copy = spec.copy()
    texture = copy.add_texture(name="rgba", type=mujoco.mjtTexture.mjTEXTURE_2D, width=2, height=2, nchannel=4)
    texture.data = bytes(16)
    model = copy.compile()
    assert [compat.texture_channels(model, t) for t in range(model.ntex)] == [3, 4]
    assert compat.texture_channels(SimpleNamespace(), 0) == 3  # MuJoCo 3.2.0


def test_an_actuator_is_limited_as_its_model_says_and_where_the_field_is_missing(spec):
    model = spec.compile()
    assert [compat.ctrl_limited(model, a) for a in range(model.nu)] == [True, False]
    assert compat.ctrl_limited(SimpleNamespace(), 0) is True


def test_mjspec_deletes_textures_and_refuses_a_bad_spec_with_a_value_error(spec):
    """What visualenv.physics.model.without_textures relies on: ``spec.delete`` where the gate says so, and a compile
    MuJoCo refuses raising ValueError (the one error it catches)."""
    assert compat.spec_deletes(mujoco), "this MuJoCo's MjSpec has no delete: read how it removes an element now"
    copy = spec.copy()
    for texture in list(copy.textures):
        copy.delete(texture)
    assert copy.compile().ntex == 0
    assert not compat.spec_deletes(SimpleNamespace(MjSpec=object)) and not compat.spec_deletes(SimpleNamespace())
    with pytest.raises(ValueError, match="material 'none' not found"):
        mujoco.MjSpec.from_string('<mujoco><worldbody><geom size="1" material="none"/></worldbody></mujoco>').compile()


def test_the_batch_api_is_there_and_a_mujoco_without_it_gives_none(monkeypatch):
    api = compat.batch_api()
    assert api is not None and hasattr(api, "Batch"), "mujoco.batch (MuJoCo 3.17 on) is gone or moved"
    monkeypatch.setitem(sys.modules, "mujoco.batch", None)  # as before MuJoCo 3.17: the import fails
    assert compat.batch_api() is None
