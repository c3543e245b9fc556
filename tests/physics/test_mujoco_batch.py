"""A physics batch stepped by MuJoCo's own batch API (``mujoco.batch``, MuJoCo 3.17): each env is one env alone, to the bit.

State-only, no Blender. Env i of a batch seeded s is compared with one env seeded s + i over
many steps, with envs reset while the others go on: qpos, qvel, rewards, observations, MuJoCo's
whole integration state (warm start included), the derived arrays a step leaves (poses,
sensors, Gymnasium's ``cfrc_ext``) and the poses a renderer takes. Where ``mujoco.batch`` would
not be exact (dm_control's split step with a mocap body moved; declared contacts), the batch
steps the lanes' MjData itself, and a test shows why.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")
pytest.importorskip("mujoco.batch", reason="MuJoCo's batch API came with MuJoCo 3.17")

from visualenv.env.batch import BatchedVectorEnv  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.physics import batch as physics_batch  # noqa: E402
from visualenv.physics.batch import THREADS_VARIABLE  # noqa: E402
from visualenv.physics.conventions import step_function  # noqa: E402
from visualenv.physics.batch_mujoco import MujocoBatch, batch_module  # noqa: E402
from visualenv.physics.simulation import integration_state  # noqa: E402

#: what a step leaves in MjData besides the state, compared lane against single env
DERIVED = ("xpos", "xquat", "geom_xpos", "site_xpos", "sensordata", "qacc", "qfrc_actuator", "cfrc_ext", "ncon")


def assert_same_data(ours: object, theirs: object, where: str) -> None:
    np.testing.assert_array_equal(integration_state(ours), integration_state(theirs), err_msg=where)
    for field in DERIVED:
        np.testing.assert_array_equal(getattr(ours, field), getattr(theirs, field), err_msg=f"{where}: {field}")
    np.testing.assert_array_equal(ours.warning.number, theirs.warning.number, err_msg=where)  # type: ignore[attr-defined]


IDS = [
    "DMC-cartpole-swingup-v0",
    "DMC-cheetah-run-v0",
    "DMC-finger-spin-v0",
    "DMC-reacher-easy-v0",
    "DMC-reacher-hard-v0",  # its reset writes a geom's size too
    "DMC-acrobot-swingup-v0",  # RK4: dm_control's step is one mj_step(nstep)
    "DMC-hopper-hop-v0",  # its reward reads the bodies' centres of mass (xipos) and its observation touch sensors
    "DMC-humanoid-run-v0",  # a free joint, its reset redrawn until nothing touches
    "VisualHalfCheetah-v0",
]


@pytest.mark.parametrize(
    "ident, by_mujoco", [(i, True) for i in IDS] + [("DMC-cheetah-run-v0", False), ("VisualHalfCheetah-v0", False)]
)
def test_each_env_stepped_by_mujoco_batch_is_one_env_alone(
    ident: str, by_mujoco: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """dm_control's split step and settling steps (cheetah), resets that write the env's own model (finger's damping, reacher's
    target) and Gymnasium's convention: five envs for 120 steps, four of them reset at different steps while the others go on.
    Likewise where the batch steps the lanes' MjData itself (a mujoco without mujoco.batch)."""
    if not by_mujoco:
        monkeypatch.setattr(physics_batch, "batch_module", lambda *args: None)
    n, steps = 5, 120
    batch = BatchedVectorEnv(ident, n, render=False, action_repeat=1)
    singles = [
        VisualEnv(batch.program, render=False, action_repeat=1) for _ in range(n)
    ]  # one env each, as make() gives it
    plan = batch.program.physics
    assert (
        plan is not None and isinstance(batch._physics.engine, MujocoBatch) == by_mujoco
    )  # MuJoCo's batch steps them, or the lanes
    try:
        obs, _ = batch.reset(seed=20)
        for i, env in enumerate(singles):
            np.testing.assert_array_equal(obs[i], env.reset(seed=20 + i)[0])
        resets = {
            (30, 1),
            (31, 3),
            (70, 0),
            (71, 1),
            (100, 4),
        }  # (step, env): the env ends its episode there, the others go on
        pending = np.zeros(n, dtype=bool)
        actions = np.random.default_rng(1).uniform(-1, 1, (steps, *batch.action_space.shape))
        for t, action in enumerate(actions):
            obs, rewards, *_ = batch.step(action)
            for i, env in enumerate(singles):
                if pending[i]:  # the step after an episode's end resets the env (NEXT_STEP), its action ignored
                    single_obs, reward = env.reset()[0], 0.0
                else:
                    single_obs, reward, *_ = env.step(action[i])
                assert rewards[i] == reward, (t, i)
                np.testing.assert_array_equal(obs[i], single_obs, err_msg=f"step {t}, env {i}")
                source = batch._physics.pose_sources()[
                    i
                ]  # what the renderer poses env i from: the batch's rows, or its lane
                for ours, theirs in zip(plan.poses(source), plan.poses(env.data)):
                    np.testing.assert_array_equal(ours, theirs, err_msg=f"step {t}, env {i}: poses")
            for lane, env in zip(batch.lanes, singles):  # handed out, a lane's MjData is the whole of it
                assert_same_data(lane.data, env.data, f"step {t}")
            pending[:] = False
            for step, i in resets:
                if step == t:
                    batch._autoreset[i] = pending[i] = True  # as if env i's episode ended at this step
    finally:
        batch.close()
        for env in singles:
            env.close()


#: a motor that can blow the arm up (gear 1e30), a slide; no contacts declared, so MuJoCo's batch steps it
ARM = """\
<mujoco model="arm">
  <option timestep="0.01"/>
  <worldbody>
    <body name="cart">
      <joint name="slide" type="slide" axis="1 0 0" damping="0.5"/>
      <geom name="block" type="box" size="0.1 0.1 0.1" mass="1"/>
    </body>
    <body name="arm" pos="2 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="push" joint="slide" gear="5"/>
    <motor name="torque" joint="hinge" gear="1e30" ctrllimited="false"/>
  </actuator>
</mujoco>
"""


@pytest.mark.filterwarnings("ignore:MuJoCo. Nan, Inf or huge value:RuntimeWarning")
@pytest.mark.parametrize("threads", ["1", "2"])
def test_an_env_that_blows_up_in_mujoco_batch_ends_with_its_own_fault(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, threads: str
) -> None:
    """on_fault: terminate: env 2 blows up inside MuJoCo's batch (with two threads, MuJoCo's warning may reach Python from
    the batch's own thread); it ends with the fault one env gives, resets, and it and the others go on as alone (the
    batch's warning counters of env 2 start again at its reset, as its MjData's do)."""
    monkeypatch.setenv(THREADS_VARIABLE, threads)
    (tmp_path / "arm.xml").write_text(ARM, encoding="utf-8")
    path = tmp_path / "arm.yaml"
    path.write_text(
        textwrap.dedent("""\
        id: Arm-v0
        physics:
          model: arm.xml
          frame_skip: 2
          reset: {values: {qvel_slide: 'uniform(0, 3)'}}
          observe: [qpos_slide, qvel_slide, qpos_hinge, sim_time]
        actions:
          continuous: {ctrl_push: {low: -1, high: 1}, ctrl_torque: {low: -1.0e+30, high: 1.0e+30}}
        reward: qpos_slide
        on_fault: terminate
        max_steps: 30
        """),
        encoding="utf-8",
    )
    batch = BatchedVectorEnv(path, 3, render=False)
    singles = [VisualEnv(path, render=False) for _ in range(3)]
    assert isinstance(batch._physics.engine, MujocoBatch) and batch._physics.engine.batch.nthread == int(threads)
    obs, _ = batch.reset(seed=5)
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(obs[i], env.reset(seed=5 + i)[0])
    actions = np.zeros((40, 3, 2))
    actions[:, :, 0] = np.random.default_rng(1).uniform(-1, 1, (40, 3))
    actions[[4, 12], 2, 1] = 1e30  # env 2 blows up at its fifth step, and again in its next episode
    pending, errors = [False] * 3, []
    for t, step in enumerate(actions):
        obs, rewards, terminated, truncated, info = batch.step(step)
        for i, env in enumerate(singles):
            if pending[i]:
                single_obs, _ = env.reset()
                reward, term, trunc, error = 0.0, False, False, None
            else:
                single_obs, reward, term, trunc, single_info = env.step(step[i])
                error = single_info.get("error")
            np.testing.assert_array_equal(obs[i], single_obs, err_msg=f"step {t}, env {i}")
            assert (rewards[i], terminated[i], truncated[i]) == (reward, term, trunc)
            assert (info["error"][i] if "error" in info and info["_error"][i] else None) == error
            if error is not None:
                errors.append((t, i))
                assert "blew up" in error
            pending[i] = term or trunc
        for lane, env in zip(batch.lanes, singles):
            assert_same_data(lane.data, env.data, f"step {t}")
    assert errors == [(4, 2), (12, 2)]
    batch.close()


def test_mujoco_batch_is_chosen_where_it_is_exact() -> None:
    """Not for declared contacts (the batch's arrays hold no contact list) nor for dm_control's convention with mocap bodies
    moved in dynamics.update (see the next test); every other spec, dm_control's and Gymnasium's, where mujoco has it."""
    assert batch_module("gymnasium", contacts=False, moved=False) is not None
    assert batch_module("dm_control", contacts=False, moved=False) is not None
    assert batch_module("gymnasium", contacts=False, moved=True) is not None
    assert batch_module("gymnasium", contacts=True, moved=False) is None
    assert batch_module("dm_control", contacts=False, moved=True) is None


def test_dm_controls_split_step_with_a_moved_mocap_body_is_not_what_mujoco_batch_computes() -> None:
    """Why dm_control's convention with a moved mocap body keeps stepping the lanes: its step finishes the last one
    (mj_step2) from the kinematics of the old mocap pose; MuJoCo's batch computes them from the new one. If this starts to
    hold, batch_module can let such specs through."""
    from mujoco import batch as api

    model = mujoco.MjModel.from_xml_string("""<mujoco><worldbody><geom type="plane" size="2 2 .1"/>
      <body pos="0 0 .3"><freejoint/><geom type="sphere" size=".1"/></body>
      <body name="goal" mocap="true" pos="0 0 .15"><geom type="box" size=".1 .1 .05"/></body></worldbody></mujoco>""")
    for convention, moves, same in (("dm_control", 0.05, False), ("dm_control", 0.0, True), ("gymnasium", 0.05, True)):
        step = step_function(convention, mujoco)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        batch = api.Batch(model, 1, 1, persistent=True)
        stage = mujoco.mjtStage.mjSTAGE_VEL if convention == "dm_control" else mujoco.mjtStage.mjSTAGE_NONE
        for t in range(10):
            data.mocap_pos[0, 0] = batch.mocap_pos[0, 0, 0] = moves * t
            step(model, data, 2)
            batch.step(nstep=2, stage=stage)
        assert np.array_equal(batch.qpos[0], data.qpos) == same, (convention, moves)
