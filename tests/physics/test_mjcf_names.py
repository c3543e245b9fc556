"""Two MJCF elements that come to one name in visualenv are an error naming both, never a silent choice.

Names become identifiers (``left-leg`` -> ``left_leg``) and free joints make one name per component
(``qpos_a_x``), so distinct MuJoCo names can collide: joints, bodies, sites, sensors, actuators; geoms,
cameras and lights (also the drawn scene's objects); keyframes; the contacts a spec declares. Every
model here is a few lines of MJCF written by the test.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

pytest.importorskip("mujoco")

from visualenv.cli import main  # noqa: E402
from visualenv.compiler.program import compile_spec  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.errors import SpecError  # noqa: E402
from visualenv.spec.loader import load_spec  # noqa: E402

#: {body} is placed in the world body, {extra} after it
MODEL = """\
<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
{body}
  </worldbody>
{extra}
</mujoco>
"""

SPEC = """\
id: Names-v0
physics:
  model: model.xml
{extra}
"""


def body(joints: str, inner: str = "", name: str = "b") -> str:
    return f'    <body name="{name}" pos="0 0 1">{joints}<geom name="{name}_geom" size="0.1"/>{inner}</body>'


CASES = {
    "joints": (
        body('<joint name="left-leg"/><joint name="left_leg" axis="1 0 0"/>'),
        "",
        "joint 'left-leg' and joint 'left_leg' are both 'qpos_left_leg'",
    ),
    "free joint and hinge": (
        body('<freejoint name="a"/>') + body('<joint name="a_x"/>', name="c"),
        "",
        "joint 'a' and joint 'a_x' are both 'qpos_a_x'",
    ),
    "bodies": (
        body('<joint name="j1"/>', name="arm.1") + body('<joint name="j2"/>', name="arm_1"),
        "",
        "body 'arm.1' and body 'arm_1' are both 'body_arm_1_x'",
    ),
    "a body and its centre of mass": (
        body('<joint name="j1"/>', name="arm") + body('<joint name="j2"/>', name="arm_com"),
        "",
        "body 'arm' and body 'arm_com' are both 'body_arm_com_x'",
    ),
    "sites": (
        body('<joint name="j"/>', inner='<site name="tip-1"/><site name="tip_1"/>'),
        "",
        "site 'tip-1' and site 'tip_1' are both 'site_tip_1_x'",
    ),
    "sensors": (
        body('<joint name="j"/>', inner='<site name="s"/>'),
        '<sensor><framepos name="p" objtype="site" objname="s"/><jointpos name="p_0" joint="j"/></sensor>',
        "sensor 'p' and sensor 'p_0' are both 'sensor_p_0'",
    ),
    "actuators": (
        body('<joint name="j"/>'),
        '<actuator><motor name="m-1" joint="j"/><motor name="m_1" joint="j"/></actuator>',
        "actuator 'm-1' and actuator 'm_1' are both 'ctrl_m_1'",
    ),
    "geoms": (
        body('<joint name="j"/>', inner='<geom name="foot-l" size="0.1"/><geom name="foot_l" size="0.1"/>'),
        "",
        "geom 'foot-l' and geom 'foot_l' are both 'foot_l'",
    ),
    "unnamed geom": (
        '    <geom name="geom2" size="0.1"/><geom size="0.1"/>',
        "",
        "geom 'geom2' and the unnamed geom 2 are both 'geom2'",
    ),
    "geom and camera": (
        body('<joint name="j"/>', inner='<camera name="b_geom"/>'),
        "",
        "geom 'b_geom' and camera 'b_geom' are both 'b_geom'",
    ),
    "keyframes": (
        body('<joint name="j"/>'),
        '<keyframe><key name="up-1"/><key name="up_1"/></keyframe>',
        "keyframe 'up-1' and keyframe 'up_1' are both 'up_1'",
    ),
}


def write(tmp_path: Path, model: str, spec_extra: str = "") -> Path:
    (tmp_path / "model.xml").write_text(model, encoding="utf-8")
    path = tmp_path / "spec.yaml"
    path.write_text(SPEC.format(extra=spec_extra), encoding="utf-8")
    return path


@pytest.mark.parametrize("case", CASES)
def test_two_elements_with_one_name_are_a_located_error_naming_both(tmp_path: Path, case: str) -> None:
    body_xml, extra, expected = CASES[case]
    path = write(tmp_path, MODEL.format(body=body_xml, extra=extra))
    with pytest.raises(SpecError) as caught:
        compile_spec(load_spec(path))
    message = str(caught.value)
    assert "spec.yaml:3:10: physics.model:" in message and expected in message and "Rename one" in message, message


def test_validate_and_inspect_report_the_clash(tmp_path: Path) -> None:
    body_xml, extra, expected = CASES["joints"]
    path = write(tmp_path, MODEL.format(body=body_xml, extra=extra))
    validated = CliRunner().invoke(main, ["validate", str(path)])
    assert validated.exit_code != 0 and expected in validated.output and "ok" not in validated.output.split(), (
        validated.output
    )
    inspected = CliRunner().invoke(main, ["inspect", str(tmp_path / "model.xml")])
    assert inspected.exit_code == 1 and expected in inspected.output and "Traceback" not in inspected.output, (
        inspected.output
    )


def test_distinct_names_stay_distinct(tmp_path: Path) -> None:
    """The control: the same kinds of elements, named apart, compile and keep every name."""
    model = MODEL.format(
        body=body('<freejoint name="a"/>', inner='<site name="tip"/>') + body('<joint name="a_y2"/>', name="c"),
        extra='<actuator><motor name="m" joint="a_y2"/></actuator>',
    )
    program = compile_spec(load_spec(write(tmp_path, model)))
    assert program.physics is not None
    values = program.physics.model.names.values
    assert {"qpos_a_x", "qpos_a_qw", "qpos_a_y2", "body_b_z", "body_c_z", "site_tip_x", "ctrl_m"} <= set(values)


def test_a_bodys_centre_of_mass_is_read_apart_from_its_frame(tmp_path: Path) -> None:
    """``body_<b>_com_x/_y/_z`` read MuJoCo's ``xipos`` (where hopper's reward measures heights), ``body_<b>_x`` the
    body's frame (``xpos``): a body whose geom sits off its frame has the two apart."""
    model = MODEL.format(
        body='    <body name="b" pos="0 0 1"><freejoint/><geom pos="0.3 0 0.2" size="0.1"/></body>', extra=""
    )
    path = write(tmp_path, model, "  observe: [body_b_x, body_b_z, body_b_com_x, body_b_com_y, body_b_com_z]")
    env = VisualEnv(compile_spec(load_spec(path)), render=False)
    obs, _ = env.reset(seed=0)
    data = env.data
    assert obs.tolist() == [*data.xpos[1, [0, 2]], *data.xipos[1]]
    assert obs.tolist() == pytest.approx([0.0, 1.0, 0.3, 0.0, 1.2])
    env.step(env.action_space.sample())  # it falls: both still read the step's state
    assert env.step(env.action_space.sample())[0].tolist() == [*data.xpos[1, [0, 2]], *data.xipos[1]]
    env.close()


def test_a_contact_named_like_a_model_name_or_a_state_variable(tmp_path: Path) -> None:
    model = MODEL.format(body=body('<joint name="j"/>'), extra="")
    path = write(
        tmp_path,
        model,
        "  contacts: {qpos_j: [b_geom, floor], touching: [b_geom, floor]}\nstate: {touching: {init: 0}}",
    )
    with pytest.raises(SpecError) as caught:
        compile_spec(load_spec(path))
    message = str(caught.value)
    assert "physics.contacts.qpos_j: 'qpos_j' is a name of the physics model: choose another" in message, message
    assert "physics.contacts.touching: 'touching' is already defined in state" in message, message
