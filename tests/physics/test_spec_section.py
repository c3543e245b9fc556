"""A spec's physics section: the model's names in expressions, reset values, contacts, controls, and its errors.

Every model here is written by the test (MJCF text), small enough to compile in
milliseconds; nothing renders (tests/render/test_mjcf_scene.py renders).
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from visualenv.compiler.program import compile_spec  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.errors import SpecError, StepError  # noqa: E402
from visualenv.spec.loader import load_spec  # noqa: E402

#: a ball on a free joint above a floor, a hinged arm with a motor, a site, two sensors and a keyframe
MODEL = """\
<mujoco model="toy">
  <option timestep="0.01"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="ball" pos="0 0 1">
      <freejoint name="free"/>
      <geom name="ball_geom" type="sphere" size="0.1" mass="1"/>
    </body>
    <body name="arm" pos="2 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom name="arm_geom" type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05" contype="0" conaffinity="0"/>
      <site name="tip" pos="0 0 -0.5"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="torque" joint="hinge" gear="1" ctrllimited="true" ctrlrange="-2 2"/>
  </actuator>
  <sensor>
    <jointpos name="angle" joint="hinge"/>
    <framepos name="tip_pos" objtype="site" objname="tip"/>
  </sensor>
  <keyframe>
    <key name="high" qpos="0 0 3 1 0 0 0 0.5"/>
  </keyframe>
</mujoco>
"""


def write(tmp_path: Path, spec: str, model: str = MODEL, name: str = "toy.xml") -> Path:
    (tmp_path / name).write_text(model, encoding="utf-8")
    path = tmp_path / "spec.yaml"
    path.write_text(textwrap.dedent(spec), encoding="utf-8")
    return path


BASE = """\
id: Toy-v0
physics:
  model: toy.xml
  frame_skip: 2
{extra}
"""


def spec_with(extra: str) -> str:
    """BASE and `extra`, written indented by 4 in the tests: lines at 6 continue the physics section."""
    return BASE.format(extra="\n".join(line[4:] if line.startswith("    ") else line for line in extra.splitlines()))


def errors_of(path: Path) -> str:
    with pytest.raises(SpecError) as caught:
        compile_spec(load_spec(path))
    return str(caught.value)


# -- names, actions, reset -------------------------------------------------------------------------


def test_default_actions_are_the_actuators_and_names_read_the_model(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        spec_with("""\
    state:
      total: {init: 0}
    dynamics:
      let: {angle_before: qpos_hinge}
      update: {total: total + 1}
    reward: qpos_hinge - angle_before
    outcomes:
      landed: {when: body_ball_z < 0.2 and sim_time > 0.1, end: terminate}
    """),
    )
    env = VisualEnv(path, render=False)
    assert env.action_space.shape == (1,) and env.action_space.low[0] == -2 and env.action_space.high[0] == 2
    program = env.program
    assert program.params["dt"] == pytest.approx(0.02)
    obs, _ = env.reset(seed=0)
    # default observation: every qpos (7 free + 1 hinge), every qvel (6 + 1), then the observed state
    assert obs.shape == (16,) and obs.dtype == np.float64 and obs[2] == 1.0 and obs[-1] == 0.0
    angle = env.data.qpos[7]
    _, reward, terminated, _, info = env.step(np.array([2.0]))
    assert reward == pytest.approx(env.data.qpos[7] - angle) and reward > 0  # the motor turned the arm
    assert env.data.ctrl[0] == 2.0 and info["state"]["total"] == 1.0
    for _ in range(200):
        _, _, terminated, _, info = env.step(np.array([0.0]))
        if terminated:
            break
    assert terminated and info["outcome"] == "landed"


def test_reset_values_draws_and_keyframe(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        spec_with("""\
      reset:
        keyframe: high
        values:
          qpos_free_x: qpos_free_x + uniform(-1, 1)
          qpos_hinge, qvel_hinge: "[qpos_hinge * 2, 0.25]"
      observe: [qpos_free_x, qpos_free_z, qpos_hinge, qvel_hinge, sensor_angle, site_tip_x, sensor_tip_pos_0]
    """),
    )
    env = VisualEnv(path, render=False)
    obs, _ = env.reset(seed=3)
    expected_x = np.random.default_rng(3).uniform(-1, 1)
    assert obs[0] == expected_x and obs[1] == 3.0  # the keyframe's height, the drawn x
    assert obs[2] == 1.0 and obs[3] == 0.25 and obs[4] == 1.0  # the sensor reads the reset state (mj_forward)
    assert obs[5] == pytest.approx(obs[6]) and obs[5] == pytest.approx(2 - 0.5 * np.sin(1.0))


def test_contacts_and_discrete_controls(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        spec_with("""\
      contacts: {on_floor: [floor, ball_geom]}
    actions:
      discrete:
        - {ctrl_torque: -1}
        - {ctrl_torque: 1.5}
    reward: "1.0 if on_floor else 0.0"
    outcomes:
      touched: {when: on_floor, end: terminate}
    """),
    )
    env = VisualEnv(path, render=False)
    env.reset(seed=0)
    _, reward, terminated, _, _ = env.step(1)
    assert env.data.ctrl[0] == 1.5 and reward == 0.0 and not terminated
    steps = 1
    while not terminated and steps < 200:
        _, reward, terminated, _, _ = env.step(0)
        steps += 1
    assert terminated and reward == 1.0 and env.data.ctrl[0] == -1.0 and 20 < steps < 100


def test_a_contact_read_in_let_is_the_one_before_the_step(tmp_path: Path) -> None:
    """docs/physics.md: let reads the contact the previous step found, reward the one this step found: each landing pays once."""
    path = write(
        tmp_path,
        spec_with("""\
      contacts: {on_floor: [floor, ball_geom]}
    dynamics:
      let: {was: "1 if on_floor else 0"}
    actions: {discrete: [{}]}
    reward: "1 if on_floor and was == 0 else 0"
    max_steps: 150
    """),
    )
    env = VisualEnv(path, render=False)
    env.reset(seed=0)
    touching, rewards = [False], []
    for _ in range(150):
        rewards.append(env.step(0)[1])
        touching.append(env.data.ncon > 0)  # the ball and the floor: the model's only contact pair
    landings = [float(now and not before) for before, now in zip(touching, touching[1:])]
    assert rewards == landings and 1 <= sum(rewards) < sum(
        touching
    )  # each landing pays once, not every step on the floor


# -- errors ----------------------------------------------------------------------------------------------


def test_unknown_names_list_the_models_names(tmp_path: Path) -> None:
    message = errors_of(write(tmp_path, spec_with("reward: qpos_hing + body_bal_z\n")))
    assert "spec.yaml:" in message and "unknown name 'qpos_hing'" in message and "did you mean 'qpos_hinge'" in message


def test_unknown_geom_keyframe_and_reset_target(tmp_path: Path) -> None:
    message = errors_of(
        write(
            tmp_path,
            spec_with("""\
      contacts: {hit: [floor, bal]}
      reset:
        keyframe: low
        values: {qpos_hing: 0}
    """),
        )
    )
    assert "no geom 'bal' in the model (geoms: floor, ball_geom, arm_geom)" in message
    assert "no keyframe 'low' in the model" in message and "high" in message
    assert "no joint value 'qpos_hing' to set (did you mean 'qpos_hinge'?" in message


def test_dt_is_the_models(tmp_path: Path) -> None:
    assert "leave 'dt' out" in errors_of(write(tmp_path, spec_with("dt: 0.1\n")))


@pytest.mark.parametrize(
    "model, expected",
    [
        ("<mujoco><worldbody><body>\n</mujoco>", "XML parse error"),
        (
            '<mujoco>\n  <include file="missing.xml"/>\n</mujoco>',
            "Error opening file 'missing.xml' Element 'include', line 2",
        ),
        (
            '<mujoco>\n<worldbody>\n  <geom type="box" size="1 1 1" colour="red"/>\n</worldbody>\n</mujoco>',
            "unrecognized attribute: 'colour' Element 'geom', line 3",
        ),
        (
            '<mujoco>\n<worldbody>\n  <gizmo name="x"/>\n</worldbody>\n</mujoco>',
            "unrecognized element Element 'gizmo', line 3",
        ),
    ],
)
def test_bad_mjcf_is_a_located_error(tmp_path: Path, model: str, expected: str) -> None:
    message = errors_of(write(tmp_path, spec_with(""), model=model))
    assert "spec.yaml:3" in message and "physics.model" in message and expected in message and "toy.xml" in message


def test_missing_model_file(tmp_path: Path) -> None:
    path = tmp_path / "spec.yaml"
    path.write_text(BASE.format(extra="").replace("toy.xml", "nothing.xml"), encoding="utf-8")
    assert "no MJCF file" in errors_of(path) and "nothing.xml" in errors_of(path)


@pytest.mark.filterwarnings("ignore:MuJoCo. Nan, Inf or huge value:RuntimeWarning")
def test_a_simulation_that_blows_up_is_a_located_fault(tmp_path: Path) -> None:
    model = MODEL.replace('gear="1" ctrllimited="true" ctrlrange="-2 2"', 'gear="1e30" ctrllimited="false"')
    path = write(
        tmp_path,
        spec_with("""\
    actions:
      continuous: {ctrl_torque: {low: -1.0e+30, high: 1.0e+30}}
    """),
        model=model,
    )
    env = VisualEnv(path, render=False)
    env.reset(seed=0)
    with pytest.raises(StepError) as caught:
        for _ in range(5):
            env.step(np.array([1e30]))
    message = str(caught.value)
    assert "spec.yaml:" in message and "MuJoCo" in message and "blew up" in message and "step 0" in message, message


def test_core_imports_without_mujoco_and_a_physics_spec_says_how_to_install_it(tmp_path: Path) -> None:
    path = write(tmp_path, spec_with(""))
    code = textwrap.dedent(f"""
        import sys
        sys.modules["mujoco"] = None  # as if it were not installed
        import visualenv
        from visualenv.compiler.program import compile_spec
        from visualenv.spec.loader import load_spec
        from visualenv.errors import SpecError
        try:
            compile_spec(load_spec({str(path)!r}))
        except SpecError as exc:
            print(exc)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "physics.model" in out.stdout and "pip install 'visualenv[mujoco]'" in out.stdout, out.stdout


def test_a_state_only_batch_steps_each_envs_own_simulation() -> None:
    """Env i of a batch seeded s equals one env seeded s + i (each lane steps its own MjData); HalfCheetah's tracking camera cannot be batched."""
    from visualenv.env.batch import BatchedVectorEnv

    spec = Path(__file__).resolve().parents[2] / "specs" / "mujoco" / "half_cheetah.yaml"
    batch = BatchedVectorEnv(spec, 3, render=False)
    singles = [VisualEnv(spec, render=False) for _ in range(3)]
    obs, _ = batch.reset(seed=4)
    for i, env in enumerate(singles):
        assert np.array_equal(obs[i], env.reset(seed=4 + i)[0])
    actions = np.random.default_rng(0).uniform(-1, 1, (20, 3, 6))
    for step in actions:
        obs, rewards, *_ = batch.step(step)
        for i, env in enumerate(singles):
            single_obs, single_reward, *_ = env.step(step[i])
            assert np.array_equal(obs[i], single_obs) and rewards[i] == single_reward


def test_an_input_for_an_actuator_that_does_not_exist(tmp_path: Path) -> None:
    message = errors_of(write(tmp_path, spec_with("actions: {continuous: {ctrl_torqe: {low: -1, high: 1}}}\n")))
    assert (
        "no actuator 'torqe' in the model for 'ctrl_torqe' (did you mean 'ctrl_torque'?" in message
        and "spec.yaml:" in message
    )


#: MjModel arrays a model without textures may differ in: the textures' own, the materials' links to them, the names,
#: the sizes of them all
TEXTURE_ARRAYS = ("tex_", "mat_texid", "name_", "names", "paths", "_sizes")


@pytest.mark.filterwarnings(
    "ignore:MuJoCo. compiler attribute:RuntimeWarning"
)  # Gymnasium's half_cheetah: settotalmass
@pytest.mark.parametrize(
    "model_file",
    [
        *sorted(
            str(p.relative_to(Path(__file__).parents[2]))
            for p in (Path(__file__).parents[2] / "specs").glob("*/assets/*.xml")
        ),
        "package:gymnasium.envs.mujoco/assets/half_cheetah.xml",
    ],
)
def test_each_env_copies_the_model_without_its_textures_and_steps_the_same(model_file: str) -> None:
    """An env's MjModel holds no texture (dm_control's skybox is 11.8 MB an env otherwise): every other array equals
    the model's, and 30 steps under the same controls give the same state to the bit; compiled again quietly (the
    model's own compile says what MuJoCo has to say)."""
    import warnings

    import mujoco

    from visualenv.physics.model import load_model, resolve_model_path
    from visualenv.physics.simulation import Simulation

    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        physics = load_model(resolve_model_path(model_file, Path(__file__).parents[2]))
    assert not [w for w in said if not str(w.message).startswith("MuJoCo: ")], [str(w.message) for w in said]
    full, dynamics = physics.model, physics.dynamics
    assert dynamics.ntex == 0 and Simulation(physics, 1).model.ntexdata == 0
    if full.ntex:
        assert dynamics is not full and full.ntexdata > 0
    for name in dir(full):
        value = getattr(full, name)
        if isinstance(value, np.ndarray) and not name.startswith(TEXTURE_ARRAYS):
            np.testing.assert_array_equal(value, getattr(dynamics, name), err_msg=name)
    states = []
    for model in (full, dynamics):
        data = mujoco.MjData(model)
        rng = np.random.default_rng(0)
        for _ in range(30):
            data.ctrl[:] = rng.uniform(-1, 1, model.nu)
            mujoco.mj_step(model, data)
        states.append(np.concatenate([data.qpos, data.qvel, data.act]))
    np.testing.assert_array_equal(states[0], states[1])
