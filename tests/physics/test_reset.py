"""A physics reset's model fields, redraw loop and settling steps (the features DeepMind Control's resets need), and their errors.

Every model here is written by the test (MJCF text), small enough to compile in milliseconds;
nothing renders (tests/specs/test_dmc_render.py draws a geom a reset moves). The DMC tasks that use
these features are compared with dm_control in tests/specs/test_dmc_tasks.py.
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from visualenv.compiler.program import compile_spec  # noqa: E402
from visualenv.env.batch import BatchedVectorEnv  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.errors import SpecError, StepError  # noqa: E402
from visualenv.spec.loader import load_spec  # noqa: E402

#: a ball on a slide in front of a wall (touching it while |x| < 0.2), an arm on a limited hinge, a marker geom
MODEL = """\
<mujoco model="reset">
  <option timestep="0.01"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <geom name="wall" type="box" pos="0 0 0.5" size="0.1 1 0.5"/>
    <geom name="marker" type="sphere" pos="1 1 0.05" size="0.05" contype="0" conaffinity="0"/>
    <body name="ball" pos="0 0 0.5">
      <joint name="slide" type="slide" axis="1 0 0" limited="true" range="-1 1"/>
      <geom name="ball_geom" type="sphere" size="0.1"/>
    </body>
    <body name="arm" pos="2 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1" limited="true" range="-90 90"/>
      <geom name="arm_geom" type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="torque" joint="hinge" ctrllimited="true" ctrlrange="-1 1"/>
  </actuator>
</mujoco>
"""

BASE = """\
id: Reset-v0
physics:
  model: reset.xml
  convention: {convention}
{extra}{top}
"""


def write(tmp_path: Path, extra: str, convention: str = "dm_control", top: str = "") -> Path:
    """The spec: `extra` (dedented) inside the physics section, `top` after it."""
    (tmp_path / "reset.xml").write_text(MODEL, encoding="utf-8")
    path = tmp_path / "spec.yaml"
    path.write_text(
        BASE.format(convention=convention, extra=textwrap.indent(textwrap.dedent(extra), "  "), top=top),
        encoding="utf-8",
    )
    return path


def errors_of(path: Path) -> str:
    with pytest.raises(SpecError) as caught:
        compile_spec(load_spec(path))
    return str(caught.value)


def located(message: str, path: Path, text: str) -> tuple[int, int]:
    """The line and column of the diagnostic whose message holds `text` (asserting there is one)."""
    found = re.search(rf"{re.escape(str(path))}:(\d+):(\d+): [^\n]*{re.escape(text)}", message)
    assert found, message
    return int(found.group(1)), int(found.group(2))


def line_of(path: Path, text: str) -> int:
    return next(i for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1) if text in line)


# -- names ----------------------------------------------------------------------------------------


def test_names_read_the_models_fields_geoms_positions_and_contacts(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """\
      observe: [model_geom_size_ball_geom_0, model_jnt_range_hinge_lo, model_jnt_range_hinge_hi, model_dof_damping_hinge,
                model_geom_pos_marker_x, geom_arm_geom_z, geom_ball_geom_x, ncon, model_site_size_nothing_0]
    """,
    )
    assert "unknown name 'model_site_size_nothing_0'" in errors_of(path)
    path.write_text(path.read_text(encoding="utf-8").replace(", model_site_size_nothing_0", ""), encoding="utf-8")
    env = VisualEnv(path, render=False)
    obs, _ = env.reset(seed=0)
    model, data = env.model, env.data
    assert obs.tolist() == [
        0.1,
        model.jnt_range[1][0],
        model.jnt_range[1][1],
        0.1,
        1.0,
        data.geom_xpos[4][2],
        data.geom_xpos[3][0],
        1.0,
    ]
    assert model.jnt_range[1][1] == pytest.approx(np.pi / 2)  # the model's range, in radians as MuJoCo compiled it
    assert data.ncon == 1  # the ball at x = 0 touches the wall


# -- writable model fields -------------------------------------------------------------------------


def test_a_reset_writes_model_fields_into_the_envs_own_model(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """\
        reset:
          values:
            model_geom_pos_marker_x: uniform(2, 3)
            model_dof_damping_hinge: 0.5
        observe: [model_geom_pos_marker_x, geom_marker_x, model_dof_damping_hinge]
    """,
    )
    a, b = VisualEnv(path, render=False), VisualEnv(path, render=False)
    obs, _ = a.reset(seed=1)
    assert 2 <= obs[0] < 3 and obs[1] == obs[0] and obs[2] == 0.5  # written, and the forward moved the geom
    assert a.model.geom_pos[2][0] == obs[0] and a.model.dof_damping[1] == 0.5
    assert b.model.geom_pos[2][0] == 1.0 and b.model.dof_damping[1] == 0.1  # each env has its own MjModel
    first = obs[0]
    obs, _ = a.reset()
    assert obs[0] != first and a.model.geom_pos[2][0] == obs[0]  # each reset draws again


def test_a_reset_key_that_cannot_be_written_is_a_located_error(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """\
        reset:
          values:
            model_jnt_range_hinge_lo: 0.2
            model_geom_pos_markr_x: 1
            body_ball_x: 1
    """,
    )
    message = errors_of(path)
    line = line_of(path, "model_jnt_range_hinge_lo")
    assert located(message, path, "'model_jnt_range_hinge_lo' is read from the model, not written") == (line, 7)
    assert located(
        message, path, "no writable model field 'model_geom_pos_markr_x' to set (did you mean 'model_geom_pos_marker_x'"
    ) == (line + 1, 7)
    assert located(message, path, "'body_ball_x' is computed by MuJoCo from the state") == (line + 2, 7)


#: MODEL with a camera to render through and a site on the world body (finger turn's target is one)
DRAWN = MODEL.replace(
    "<worldbody>", '<worldbody>\n    <camera name="top" pos="0 0 5"/>\n    <site name="goal" pos="0 1 0.1" size="0.1"/>'
)


def test_a_reset_writes_sizes_and_a_sites_position_from_a_joints_anchor(tmp_path: Path) -> None:
    """Sizes and a site's position are written as finger turn's reset writes them (from its hinge's anchor, ``xanchor``);
    drawn, each is a binding of its object: the scale over the size it was built at, a site's location in its body."""
    path = write(
        tmp_path,
        """\
        reset:
          values:
            model_geom_size_marker_0: 0.2
            model_site_pos_goal_x: joint_hinge_x + 1
            model_site_size_goal_0: 0.3
        observe: [model_geom_size_marker_0, site_goal_x, model_site_size_goal_0, joint_hinge_x, joint_hinge_y, joint_hinge_z]
    """,
        top="observation: {camera: top, resolution: [16, 16], color: rgb}",
    )
    (tmp_path / "reset.xml").write_text(DRAWN, encoding="utf-8")
    env = VisualEnv(path, render=False)
    obs, _ = env.reset(seed=0)
    assert obs.tolist() == [0.2, 3.0, 0.3, 2.0, 0.0, 1.0]  # the arm's hinge is anchored at its body's (2, 0, 1)
    assert env.model.site_pos[0].tolist() == [3.0, 1.0, 0.1] and env.model.site_size[0][0] == 0.3
    assert [(t.object, t.property) for t in env.program.bindings] == [
        ("marker", "scale"),
        ("site:goal", "scale"),
        ("site:goal", "location"),
    ]


def test_a_drawn_capsules_size_is_not_written(tmp_path: Path) -> None:
    """A capsule drawn at a new radius would need its caps rebuilt: a located error; hidden (not drawn), it is written."""
    extra = """\
        reset:
          values: {model_geom_size_arm_geom_0: 0.1}
    """
    path = write(tmp_path, extra, top="observation: {camera: top, resolution: [16, 16], color: rgb}")
    (tmp_path / "reset.xml").write_text(DRAWN, encoding="utf-8")
    message = errors_of(path)
    assert located(
        message, path, "the geom 'arm_geom' is drawn as a capsule, which cannot be drawn at another size"
    ) == (
        line_of(path, "model_geom_size_arm_geom_0"),
        14,
    )
    hidden = write(tmp_path, extra)  # no observation: nothing is drawn
    env = VisualEnv(hidden, render=False)
    env.reset(seed=0)
    assert env.model.geom_size[4][0] == 0.1


# -- redraw -----------------------------------------------------------------------------------------


def test_a_redraw_draws_again_until_its_condition_holds(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """\
        reset:
          redraw:
            values: {qpos_slide: "uniform(model_jnt_range_slide_lo, model_jnt_range_slide_hi)"}
            until: ncon == 0
        observe: [qpos_slide, ncon]
    """,
    )
    env = VisualEnv(path, render=False)
    stream = np.random.RandomState(3)
    draws = []
    for seed in (3, None, None, None, None, None, None, None):
        obs, _ = env.reset(seed=seed)
        tries = [stream.uniform(-1, 1)]
        while abs(tries[-1]) < 0.2:  # the ball touches the wall: dm_control's loop draws again
            tries.append(stream.uniform(-1, 1))
        draws.append(len(tries))
        assert obs.tolist() == [tries[-1], 0.0] and env.data.ncon == 0
    assert max(draws) > 1, draws  # the stream of seed 3 touches at least once in these resets


def test_each_try_starts_from_the_values_the_reset_wrote(tmp_path: Path) -> None:
    """A try reads the joint's value as ``values`` left it, never the previous try's: ten tries do not add up."""
    path = write(
        tmp_path,
        """\
        reset:
          values: {qpos_slide: 0.5}
          redraw:
            values: {qpos_slide: "qpos_slide + uniform(0, 0.1)"}
            until: qpos_slide > 0.59
        observe: [qpos_slide]
    """,
    )
    env = VisualEnv(path, render=False)
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        assert 0.59 < obs[0] < 0.6


def test_a_redraw_that_never_meets_its_condition_is_a_located_fault(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """\
        reset:
          redraw:
            values: {qpos_slide: "uniform(-0.1, 0.1)"}
            until: ncon == 0
            attempts: 7
    """,
    )
    env = VisualEnv(path, render=False)
    with pytest.raises(StepError) as caught:
        env.reset(seed=0)
    message = str(caught.value)
    assert f"spec.yaml:{line_of(path, 'until:')}: physics.reset.redraw.until = 'ncon == 0'" in message
    assert "none of 7 tries met the condition" in message


def test_a_bad_redraw_is_a_located_error(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """\
        reset:
          redraw:
            values: {qpos_slide: "uniform(-1, 1)"}
            until: ncon == 0
            attempts: 0
    """,
    )
    assert located(errors_of(path), path, "physics.reset.redraw.attempts") == (line_of(path, "attempts"), 17)
    path = write(
        tmp_path,
        """\
        reset:
          redraw:
            values: {qpos_slid: "uniform(-1, 1)"}
            until: ncon == 0
    """,
    )
    assert located(errors_of(path), path, "no joint value 'qpos_slid' to set (did you mean 'qpos_slide'") == (
        line_of(path, "qpos_slid"),
        16,
    )
    path = write(
        tmp_path,
        """\
        reset:
          redraw:
            values: {}
            until: ncon + 1
    """,
    )
    message = errors_of(path)
    assert located(message, path, "physics.reset.redraw.values") == (line_of(path, "values"), 15)
    path = write(
        tmp_path,
        """\
        reset:
          redraw:
            values: {qpos_slide: "uniform(-1, 1)"}
            until: ncon + 1
    """,
    )
    assert located(errors_of(path), path, "physics.reset.redraw.until") == (line_of(path, "until"), 14)


# -- settle -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("convention", ["dm_control", "gymnasium"])
def test_settling_steps_are_the_conventions_steps_then_the_time_set(tmp_path: Path, convention: str) -> None:
    """The reset's MuJoCo calls, written out: reset (and dm_control's forward), the values, the steps in one call, the time, a forward."""
    path = write(
        tmp_path,
        """\
        reset:
          values: {qpos_hinge: 0.5}
          settle: {steps: 40, time: 0}
    """,
        convention,
    )
    env = VisualEnv(path, render=False)
    env.reset(seed=0)
    from visualenv.physics.conventions import forward_function, reset_data, step_function

    model = mujoco.MjModel.from_xml_path(str(tmp_path / "reset.xml"))
    data = mujoco.MjData(model)
    reset_data(convention, mujoco, model, data, None)
    data.qpos[1] = 0.5
    step_function(convention, mujoco)(model, data, 40)
    data.time = 0.0
    forward_function(convention, mujoco)(model, data)
    state = mujoco.mjtState.mjSTATE_INTEGRATION
    ours, theirs = (np.empty(mujoco.mj_stateSize(model, state)) for _ in range(2))
    mujoco.mj_getState(env.model, env.data, ours, state)
    mujoco.mj_getState(model, data, theirs, state)
    np.testing.assert_array_equal(ours, theirs)
    assert env.data.time == 0.0 and env.data.qpos[1] != 0.5  # the arm swung while it settled


def test_settling_keeps_the_time_unless_told(tmp_path: Path) -> None:
    env = VisualEnv(write(tmp_path, "  reset: {settle: {steps: 25}}\n"), render=False)
    env.reset(seed=0)
    assert env.data.time == pytest.approx(0.25)


@pytest.mark.filterwarnings(
    "ignore:MuJoCo:RuntimeWarning"
)  # MuJoCo's own words on the blow-up (where its warnings are Python's)
def test_a_simulation_that_blows_up_while_settling_is_a_located_fault(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """\
        reset:
          values: {qvel_hinge: 1e300}
          settle: {steps: 10}
    """,
    )
    with pytest.raises(StepError) as caught:
        VisualEnv(path, render=False).reset(seed=0)
    assert f"spec.yaml:{line_of(path, 'settle:')}: physics.reset.settle" in str(caught.value)
    assert "blew up" in str(caught.value)


def test_a_bad_settle_is_a_located_error(tmp_path: Path) -> None:
    path = write(tmp_path, "  reset: {settle: {steps: 0, time: inf}}\n")
    message = errors_of(path)
    assert "physics.reset.settle.steps" in message and "physics.reset.settle.time" in message
    assert located(message, path, "physics.reset.settle.steps")[0] == 5
    path = write(tmp_path, "  reset: {settle: {time: 0}}\n")
    assert "physics.reset.settle.steps" in errors_of(path)


# -- batches ----------------------------------------------------------------------------------------


def test_a_batch_reads_contacts_and_model_fields_as_its_envs_do(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """\
        reset:
          values: {qpos_slide: "uniform(-0.4, 0.4)", model_geom_pos_marker_x: "uniform(0, 1)"}
        observe: [ncon, model_geom_pos_marker_x, geom_marker_x]
    """,
        top="reward: ncon + model_geom_pos_marker_x",
    )
    batch = BatchedVectorEnv(path, 4, render=False)
    alone = [VisualEnv(path, render=False) for _ in range(4)]
    obs, _ = batch.reset(seed=5)
    for i, env in enumerate(alone):
        np.testing.assert_array_equal(obs[i], env.reset(seed=5 + i)[0])
    for _ in range(30):
        obs, rewards, *_ = batch.step(np.zeros((4, 1)))
        for i, env in enumerate(alone):
            mine, reward, *_ = env.step(np.zeros(1))
            np.testing.assert_array_equal(obs[i], mine)
            assert rewards[i] == reward
    assert len({float(o[1]) for o in obs}) == 4  # each env's own marker
    batch.close()


# -- random orientations ---------------------------------------------------------------------------------------------

#: a free body with a ball-jointed arm on a limited hinge: one joint of each kind dm_control's randomiser draws in turn
ROTATIONS = """\
<mujoco model="rotations">
  <worldbody>
    <body name="base" pos="0 0 1">
      <freejoint name="root"/>
      <geom name="base_geom" type="box" size="0.1 0.1 0.1"/>
      <body name="arm" pos="0 0 0.2">
        <joint name="shoulder" type="ball"/>
        <geom name="arm_geom" type="capsule" fromto="0 0 0 0 0 0.3" size="0.03"/>
        <body name="hand" pos="0 0 0.3">
          <joint name="wrist" type="hinge" axis="0 1 0" limited="true" range="-30 60"/>
          <geom name="hand_geom" type="sphere" size="0.05"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""
ROTATIONS_SPEC = """\
id: Rotations-v0
physics:
  model: rotations.xml
  convention: {convention}
  reset:
    values:   # randomize_limited_and_rotational_joints, in joint order
      qpos_root_qw, qpos_root_qx, qpos_root_qy, qpos_root_qz: random_quaternion_positive()
      qpos_shoulder_qw, qpos_shoulder_qx, qpos_shoulder_qy, qpos_shoulder_qz: random_quaternion()
      qpos_wrist: uniform(model_jnt_range_wrist_lo, model_jnt_range_wrist_hi)
  observe: [qpos_root_qw, qpos_root_qx, qpos_root_qy, qpos_root_qz,
            qpos_shoulder_qw, qpos_shoulder_qx, qpos_shoulder_qy, qpos_shoulder_qz, qpos_wrist]
"""


def rotations(tmp_path: Path, convention: str) -> VisualEnv:
    (tmp_path / "rotations.xml").write_text(ROTATIONS, encoding="utf-8")
    (tmp_path / "spec.yaml").write_text(ROTATIONS_SPEC.format(convention=convention), encoding="utf-8")
    return VisualEnv(tmp_path / "spec.yaml", render=False)


def test_random_quaternions_draw_as_dm_controls_randomiser(tmp_path: Path) -> None:
    """A free joint's orientation (four uniform draws, normalised) and a ball joint's (four normal draws, normalised), then
    a hinge, are dm_control's ``randomize_limited_and_rotational_joints`` to the bit: the same draws, in its order."""
    randomizers = pytest.importorskip("dm_control.suite.utils.randomizers")
    dm_mujoco = pytest.importorskip("dm_control.mujoco")
    env = rotations(tmp_path, "dm_control")
    physics = dm_mujoco.Physics.from_xml_string(ROTATIONS)
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        with physics.reset_context():
            randomizers.randomize_limited_and_rotational_joints(physics, np.random.RandomState(seed))
        np.testing.assert_array_equal(env.data.qpos, physics.data.qpos)
        assert (obs[:4] > 0).all() and np.linalg.norm(obs[:4]) == pytest.approx(1, abs=1e-15)
        assert np.linalg.norm(obs[4:8]) == pytest.approx(1, abs=1e-15)


def test_random_quaternions_draw_from_gymnasiums_generator_too(tmp_path: Path) -> None:
    """Under Gymnasium's convention the draws are the Generator's (``random``, ``standard_normal``), unit length."""
    env = rotations(tmp_path, "gymnasium")
    seen = set()
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        positive, normal = rng.random(4), rng.standard_normal(4)
        np.testing.assert_array_equal(obs[:8], [*positive / np.linalg.norm(positive), *normal / np.linalg.norm(normal)])
        seen.add(tuple(obs[:8]))
    assert len(seen) == 5


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("random_quaternion(2)", "random_quaternion() takes 0 arguments, got 1"),
        ("random_quaternion()", "got a vector of 4"),
    ],
)
def test_a_quaternion_misused_is_a_located_error(tmp_path: Path, value: str, message: str) -> None:
    """A quaternion takes no argument, and goes to four values (``qpos_<j>_qw, ..._qz: random_quaternion()``), not one."""
    (tmp_path / "rotations.xml").write_text(ROTATIONS, encoding="utf-8")
    path = tmp_path / "spec.yaml"
    drawn = "qpos_wrist: uniform(model_jnt_range_wrist_lo, model_jnt_range_wrist_hi)"
    path.write_text(
        ROTATIONS_SPEC.format(convention="dm_control").replace(drawn, f"qpos_wrist: {value}"), encoding="utf-8"
    )
    assert located(errors_of(path), path, message) == (line_of(path, "qpos_wrist:"), 19)
