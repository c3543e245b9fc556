"""DeepMind Control, reproduced: the DMC ids but cartpole swingup (test_dmc_parity.py) step as dm_control's tasks.

Against the installed dm_control (the ``dmc`` extra, which ``make setup`` installs), as
tests/specs/test_dmc_parity.py does for cartpole: with the same seed (``reset(seed=s)`` and
``task_kwargs={"random": s}``) and the same float64 actions, the state-only env with
``action_repeat=1`` has dm_control's physics state after the first reset (MuJoCo's whole
integration state, and the model fields the task's reset writes), and qpos, qvel, the observation
and the reward agree to 1e-9 over the 1,000 steps of an episode, which both end there; the second
episode's reset (the random stream continued) and steps too. The resets' rejection loops (finger,
ball_in_cup, humanoid) are checked on seeds where dm_control's needed several tries; quadruped's search (its body raised
1 cm a try until nothing touches) takes dozens of tries on every seed.
"""

from __future__ import annotations

import math
import os
import pickle

import numpy as np
import pytest

os.environ.setdefault(
    "MUJOCO_GL", "disable"
)  # dm_control looks for an OpenGL display on import; these tests render nothing there
mujoco = pytest.importorskip("mujoco")
suite = pytest.importorskip("dm_control.suite")

import visualenv  # noqa: E402
from visualenv.env.batch import BatchedVectorEnv  # noqa: E402
from visualenv.physics.simulation import integration_state  # noqa: E402

#: id -> (dm_control's domain and task, the default action repeat, dm_control's camera 0): PlaNet's repeat for its
#: tasks (the first five here; cartpole swingup is test_dmc_parity.py's), DrQ-v2's (2) for those DrQ-v2's list added
TASKS = {
    "DMC-reacher-easy-v0": ("reacher", "easy", 4, "fixed"),
    "DMC-cheetah-run-v0": ("cheetah", "run", 4, "side"),
    "DMC-finger-spin-v0": ("finger", "spin", 2, "cam0"),
    "DMC-ball_in_cup-catch-v0": ("ball_in_cup", "catch", 4, "cam0"),
    "DMC-walker-walk-v0": ("walker", "walk", 2, "side"),
    "DMC-cartpole-balance-v0": ("cartpole", "balance", 2, "fixed"),
    "DMC-cartpole-balance_sparse-v0": ("cartpole", "balance_sparse", 2, "fixed"),
    "DMC-cartpole-swingup_sparse-v0": ("cartpole", "swingup_sparse", 2, "fixed"),
    "DMC-walker-stand-v0": ("walker", "stand", 2, "side"),
    "DMC-walker-run-v0": ("walker", "run", 2, "side"),
    "DMC-pendulum-swingup-v0": ("pendulum", "swingup", 2, "fixed"),
    "DMC-acrobot-swingup-v0": ("acrobot", "swingup", 2, "fixed"),
    "DMC-hopper-stand-v0": ("hopper", "stand", 2, "cam0"),
    "DMC-hopper-hop-v0": ("hopper", "hop", 2, "cam0"),
    "DMC-reacher-hard-v0": ("reacher", "hard", 2, "fixed"),
    "DMC-finger-turn_easy-v0": ("finger", "turn_easy", 2, "cam0"),
    "DMC-finger-turn_hard-v0": ("finger", "turn_hard", 2, "cam0"),
    "DMC-humanoid-stand-v0": ("humanoid", "stand", 2, "back"),
    "DMC-humanoid-walk-v0": ("humanoid", "walk", 2, "back"),
    "DMC-humanoid-run-v0": ("humanoid", "run", 2, "back"),
    "DMC-quadruped-walk-v0": ("quadruped", "walk", 2, "y"),  # camera 2 (QUADRUPED_CAMERA)
    "DMC-quadruped-run-v0": ("quadruped", "run", 2, "y"),
}
#: DrQ-v2's camera for quadruped is camera 2 (its cfgs/task/quadruped_*.yaml); every other task's is camera 0
QUADRUPED_CAMERA = {"quadruped": 2}
#: the ids added from DrQ-v2's list (at its action repeat, 2), after PlaNet's
DRQ_V2 = list(TASKS)[5:]
#: the tasks whose reward is dense: a run of random actions earns some, so comparing rewards compares numbers that vary
DENSE = (
    "DMC-cheetah-run-v0",
    "DMC-walker-walk-v0",
    "DMC-cartpole-balance-v0",
    "DMC-walker-stand-v0",
    "DMC-walker-run-v0",
    "DMC-acrobot-swingup-v0",
    "DMC-quadruped-walk-v0",
    "DMC-quadruped-run-v0",
)
#: the model fields each task's reset writes (dm_control's initialize_episode), compared after every reset
WRITTEN = {"reacher": ("geom_pos", "geom_size"), "finger": ("dof_damping", "site_pos", "site_size")}


def load(ident: str, seed: int):
    domain, task, *_ = TASKS[ident]
    return suite.load(domain, task, task_kwargs={"random": seed})


def their_observation(time_step) -> np.ndarray:
    """dm_control's observation dict flattened in its order (as its flat_observation does)."""
    return np.concatenate([np.ravel(v) for v in time_step.observation.values()])


def assert_same_reset(ours, theirs, where: str) -> None:
    data, physics = ours.unwrapped.data, theirs.physics
    np.testing.assert_array_equal(integration_state(data), integration_state(physics.data.ptr), err_msg=where)
    for field in WRITTEN.get(TASKS[ours.spec.id.split("/")[-1]][0], ()):  # reacher's target, finger's hinge damping
        np.testing.assert_allclose(
            getattr(ours.unwrapped.model, field), getattr(physics.model.ptr, field), rtol=0, atol=1e-15, err_msg=where
        )


@pytest.mark.parametrize("seed", [0, pytest.param(7, marks=pytest.mark.slow)])  # a second seed: the slow tier's
@pytest.mark.parametrize("ident", TASKS)
def test_the_task_equals_dm_control_over_two_episodes(ident: str, seed: int) -> None:
    ours = visualenv.make(ident, render=False, action_repeat=1)
    theirs = load(ident, seed)
    size = theirs.action_spec().shape
    actions = np.random.default_rng(1000 + seed)
    obs, _ = ours.reset(seed=seed)
    time_step = theirs.reset()
    rewarded = 0.0
    for episode in range(2):
        where = f"{ident} seed {seed} episode {episode}"
        assert_same_reset(ours, theirs, where + " reset")
        np.testing.assert_allclose(obs, their_observation(time_step), rtol=0, atol=1e-9, err_msg=where)
        for step in range(1000):
            action = actions.uniform(-1.0, 1.0, size=size)
            obs, reward, terminated, truncated, _ = ours.step(action)
            time_step = theirs.step(action)
            here = f"{where} step {step}"
            np.testing.assert_allclose(
                ours.unwrapped.data.qpos, theirs.physics.data.qpos, rtol=0, atol=1e-9, err_msg=here
            )
            np.testing.assert_allclose(
                ours.unwrapped.data.qvel, theirs.physics.data.qvel, rtol=0, atol=1e-9, err_msg=here
            )
            np.testing.assert_allclose(obs, their_observation(time_step), rtol=0, atol=1e-9, err_msg=here)
            assert abs(reward - time_step.reward) <= 1e-9, (here, reward, time_step.reward)
            assert not terminated
            assert truncated == time_step.last() == (step == 999), here  # dm_control's time limit: 1,000 control steps
            rewarded += reward
        obs, _ = ours.reset()  # no seed: both streams go on
        time_step = theirs.reset()
    if ident in DENSE:
        assert rewarded > 0


@pytest.mark.parametrize("ident", TASKS)
def test_first_resets_equal_dm_controls_on_many_seeds(ident: str) -> None:
    ours = visualenv.make(ident, render=False, action_repeat=1)
    for seed in range(6):
        obs, _ = ours.reset(seed=seed)
        theirs = load(ident, seed)
        time_step = theirs.reset()
        assert_same_reset(ours, theirs, f"{ident} seed {seed}")
        np.testing.assert_allclose(obs, their_observation(time_step), rtol=0, atol=1e-9)


def tries_of(theirs) -> int:
    """The tries dm_control's reset took: its rejection loop forwards once a try, and reset_context once more at the end."""
    calls = []
    after_reset = theirs.physics.after_reset

    def counted() -> None:
        calls.append(1)
        after_reset()

    theirs.physics.after_reset = counted
    theirs.reset()
    theirs.physics.after_reset = after_reset
    return len(calls) - 1


@pytest.mark.parametrize("ident", ["DMC-finger-spin-v0", "DMC-ball_in_cup-catch-v0", "DMC-humanoid-stand-v0"])
def test_a_reset_redraws_until_nothing_touches_as_dm_controls_does(ident: str) -> None:
    """The seeds whose first draw touched (dm_control drew again) reset to dm_control's state too, and nothing touches."""
    ours = visualenv.make(ident, render=False, action_repeat=1)
    redrawn = []
    for seed in range(40):
        theirs = load(ident, seed)
        tries = tries_of(theirs)
        if tries == 1:
            continue
        redrawn.append(tries)
        ours.reset(seed=seed)
        assert_same_reset(ours, theirs, f"{ident} seed {seed}, {tries} tries")
        assert ours.unwrapped.data.ncon == 0
        if len(redrawn) == 3:
            break
    assert len(redrawn) == 3, f"dm_control drew twice for {len(redrawn)} of 40 seeds: the loop was hardly tested"


@pytest.mark.parametrize("ident", TASKS)
def test_the_env_is_dm_controls_task_as_gymnasium_sees_it(ident: str) -> None:
    _, _, repeat, camera = TASKS[ident]
    env = visualenv.make(ident, render=False)
    theirs = load(ident, 0)
    spec = theirs.action_spec()
    assert isinstance(env.unwrapped.data, mujoco.MjData) and isinstance(env.unwrapped.model, mujoco.MjModel)
    assert (  # the Box is float32 (quadruped's -0.8 and 1.1 as float32 rounds them); MuJoCo clamps to the float64 range
        env.action_space.shape == spec.shape
        and (env.action_space.low == spec.minimum.astype(np.float32)).all()
        and (env.action_space.high == spec.maximum.astype(np.float32)).all()
    )
    assert (
        env.observation_space.shape == their_observation(theirs.reset()).shape
        and env.observation_space.dtype == np.float64
    )
    assert env.unwrapped.model.opt.timestep == theirs.physics.timestep()
    assert env.unwrapped.program.physics.dt == pytest.approx(
        theirs.control_timestep(), rel=1e-12
    )  # frame_skip is n_sub_steps
    assert env.unwrapped.action_repeat == repeat and env.unwrapped.max_episode_steps == math.ceil(
        1000 / repeat
    )  # PlaNet's
    view = env.unwrapped.program.spec.observation
    index = QUADRUPED_CAMERA.get(TASKS[ident][0], 0)
    assert (
        view.camera == mujoco.mj_id2name(theirs.physics.model.ptr, mujoco.mjtObj.mjOBJ_CAMERA, index) == camera
    )  # DrQ-v2's camera
    assert list(view.resolution) == [84, 84] and view.color == "rgb"
    env.close()


def test_a_pickled_reacher_carries_its_target() -> None:
    """The target's position is a model field the reset wrote: a copy made mid-episode has it, and goes on as the env does."""
    env = visualenv.make("DMC-reacher-easy-v0", render=False, action_repeat=1)
    env.reset(seed=4)
    target = env.unwrapped.model.geom_pos.copy()
    copy = pickle.loads(pickle.dumps(env))
    np.testing.assert_array_equal(copy.unwrapped.model.geom_pos, target)
    assert not np.array_equal(visualenv.make("DMC-reacher-easy-v0", render=False).unwrapped.model.geom_pos, target)
    for action in np.random.default_rng(0).uniform(-1, 1, size=(300, 2)):
        a, b = env.step(action), copy.step(action)
        assert a[1] == b[1]
        np.testing.assert_array_equal(a[0], b[0])


@pytest.mark.parametrize("ident", ["DMC-reacher-easy-v0", "DMC-ball_in_cup-catch-v0", "DMC-cheetah-run-v0", *DRQ_V2])
def test_a_batch_steps_as_dm_control(ident: str) -> None:
    """Each env of a state-only batch has its own target (reacher), reads the model's sizes (ball_in_cup) and settles
    (cheetah); each of the ids DrQ-v2's benchmark added draws its own reset and reward."""
    batch = BatchedVectorEnv(ident, 3, render=False, action_repeat=1)
    obs, _ = batch.reset(seed=11)
    theirs = [load(ident, 11 + i) for i in range(3)]
    steps = [t.reset() for t in theirs]
    for i, time_step in enumerate(steps):
        np.testing.assert_allclose(obs[i], their_observation(time_step), rtol=0, atol=1e-9)
    actions = np.random.default_rng(0)
    for _ in range(300):
        action = actions.uniform(-1, 1, size=(3, *theirs[0].action_spec().shape))
        obs, rewards, *_ = batch.step(action)
        for i, t in enumerate(theirs):
            time_step = t.step(action[i])
            assert abs(rewards[i] - time_step.reward) <= 1e-9
            np.testing.assert_allclose(batch.lanes[i].data.qpos, t.physics.data.qpos, rtol=0, atol=1e-9)
            np.testing.assert_allclose(obs[i], their_observation(time_step), rtol=0, atol=1e-9)
    batch.close()


#: the sparse tasks random actions rarely pay: qpos set around where they pay (cartpole: the cart within 0.25 m and the
#: pole within about 5.7 degrees of upright; pendulum: the pole within 8 degrees; finger turn: the spinner at any angle,
#: its tip within the target's radius for some), as (low, high) of each qpos
AROUND_THE_BOUNDS = {
    "DMC-cartpole-balance_sparse-v0": ([-0.4, -0.15], [0.4, 0.15]),
    "DMC-cartpole-swingup_sparse-v0": ([-0.4, -0.15], [0.4, 0.15]),
    "DMC-pendulum-swingup-v0": ([-0.3], [0.3]),
    "DMC-finger-turn_easy-v0": ([-0.2, -0.2, -math.pi], [0.2, 0.2, math.pi]),
    "DMC-finger-turn_hard-v0": ([-0.2, -0.2, -math.pi], [0.2, 0.2, math.pi]),
}


@pytest.mark.parametrize("ident", AROUND_THE_BOUNDS)
def test_a_sparse_task_pays_where_dm_controls_pays(ident: str) -> None:
    """States set around a sparse reward's bounds in both, then a step, pay 1 and 0 as dm_control's do."""
    ours = visualenv.make(ident, render=False, action_repeat=1)
    theirs = load(ident, 0)
    ours.reset(seed=0)
    theirs.reset()
    model, data = ours.unwrapped.model, ours.unwrapped.data
    paid = []
    for qpos in np.random.default_rng(2).uniform(*AROUND_THE_BOUNDS[ident], size=(60, model.nq)):
        data.qpos[:] = qpos
        data.qvel[:] = 0.0
        mujoco.mj_forward(model, data)
        with theirs.physics.reset_context():
            theirs.physics.data.qpos[:] = qpos
            theirs.physics.data.qvel[:] = 0.0
        reward = ours.step(np.zeros(model.nu))[1]
        assert reward == theirs.step(np.zeros(model.nu)).reward, qpos
        paid.append(reward)
    assert set(paid) == {0.0, 1.0}


def rewards_from(ours, theirs, qpos: np.ndarray, qvel: np.ndarray, action: np.ndarray) -> tuple[float, float]:
    """Our env's and dm_control's reward for one step with `action` from the state (qpos, qvel) set in both."""
    model, data = ours.unwrapped.model, ours.unwrapped.data
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_forward(model, data)
    with theirs.physics.reset_context():
        theirs.physics.data.qpos[:] = qpos
        theirs.physics.data.qvel[:] = qvel
    return float(ours.step(action)[1]), float(theirs.step(action).reward)


@pytest.mark.parametrize("ident", ["DMC-hopper-stand-v0", "DMC-hopper-hop-v0"])
def test_a_hopper_set_upright_is_paid_as_dm_controls(ident: str) -> None:
    """Random actions hardly ever pay a hopper (it falls at once): states set around upright (its joints near zero, the
    torso's centre of mass 0.6 to 2 m above the foot's or not; moving forward at up to 3 m/s), then a step with random
    controls, pay what dm_control's do, the standing term read from the centres of mass (xipos), zero and positive."""
    ours = visualenv.make(ident, render=False, action_repeat=1)
    theirs = load(ident, 0)
    ours.reset(seed=0)
    theirs.reset()
    model = ours.unwrapped.model
    rng = np.random.default_rng(5)
    paid = []
    for _ in range(60):
        qpos = np.zeros(model.nq)
        qpos[1] = rng.uniform(-0.6, 0.2)  # rootz: the hopper lowered, so that the torso falls below 0.6 m over the foot
        qpos[2:] = rng.uniform(-0.3, 0.3, model.nq - 2)
        qpos[5] = rng.uniform(0.1, 1.5)  # the knee, within its range, bent up to where the stand pays no more
        qvel = np.zeros(model.nv)
        qvel[0] = rng.uniform(0.0, 3.0)  # rootx: forward, through hop's linear ramp from 0 to 2 m/s
        reward, expected = rewards_from(ours, theirs, qpos, qvel, rng.uniform(-1, 1, model.nu))
        assert abs(reward - expected) <= 1e-15, (qpos, qvel)
        paid.append(reward)
    assert min(paid) == 0.0 and len({r for r in paid if r > 0}) > 10, paid


@pytest.mark.parametrize("ident", ["DMC-humanoid-stand-v0", "DMC-humanoid-walk-v0", "DMC-humanoid-run-v0"])
def test_a_humanoid_set_upright_is_paid_as_dm_controls(ident: str) -> None:
    """Random actions hardly pay a humanoid (it falls): states set around standing (the torso 1 to 1.6 m up, tilted,
    its joints near zero, moving horizontally at up to 12 m/s, through stand's, walk's and run's ramps), then a step
    with random controls, pay what dm_control's do (within rounding: dm_control's mean of the controls' terms is
    numpy's pairwise sum), and the pay varies."""
    ours = visualenv.make(ident, render=False, action_repeat=1)
    theirs = load(ident, 0)
    ours.reset(seed=0)
    theirs.reset()
    model = ours.unwrapped.model
    rng = np.random.default_rng(6)
    paid = []
    for _ in range(40):
        qpos = np.zeros(model.nq)
        qpos[2] = rng.uniform(1.0, 1.6)  # the torso's height: the head from below to above 1.4 m
        tilt = np.array([1.0, *rng.uniform(-0.5, 0.5, 2), 0.0])
        qpos[3:7] = tilt / np.linalg.norm(tilt)  # up to about 53 degrees from upright: uprightness 0.9 and below
        qpos[7:] = rng.uniform(-0.2, 0.2, model.nq - 7)
        qvel = np.zeros(model.nv)
        qvel[:2] = rng.uniform(-12.0, 12.0, 2) * rng.uniform(0.0, 1.0)  # horizontal, slow to fast
        reward, expected = rewards_from(ours, theirs, qpos, qvel, rng.uniform(-1, 1, model.nu))
        assert abs(reward - expected) <= 1e-12 * max(1.0, abs(expected)), (qpos, qvel, reward, expected)
        paid.append(reward)
    assert len({round(r, 6) for r in paid if r > 0.05}) > 10, paid
