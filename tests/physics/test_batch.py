"""Batches of physics specs: every env's MuJoCo step in one batched call, the rest as numpy columns, each env exactly as alone.

State-only (nothing renders: tests/render/test_mjcf_scene.py renders a batch). Env i of a batch
seeded s is compared with one env seeded s + i, bit for bit, through episode ends, resets,
threads and an env whose simulation blows up.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from visualenv.env.batch import BatchedVectorEnv  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.errors import StepError  # noqa: E402
from visualenv.physics import simulation  # noqa: E402
from visualenv.physics.batch import THREADS_VARIABLE  # noqa: E402

SPECS = Path(__file__).resolve().parents[2] / "specs" / "mujoco"

#: a hinged arm whose motor can blow the simulation up (gear 1e30), a slide whose contact with a wall is a condition
MODEL = """\
<mujoco model="arm">
  <option timestep="0.01"/>
  <worldbody>
    <geom name="wall" type="box" pos="0.5 0 0" size="0.05 0.5 0.5"/>
    <body name="cart">
      <joint name="slide" type="slide" axis="1 0 0"/>
      <geom name="block" type="box" size="0.1 0.1 0.1" mass="1"/>
    </body>
    <body name="arm" pos="2 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="push" joint="slide" gear="5"/>
    <motor name="torque" joint="hinge" gear="1e30" ctrllimited="false"/>
  </actuator>
</mujoco>
"""


def arm_spec(tmp_path: Path, on_fault: str) -> Path:
    (tmp_path / "arm.xml").write_text(MODEL, encoding="utf-8")
    path = tmp_path / "arm.yaml"
    path.write_text(
        textwrap.dedent(f"""\
        id: Arm-v0
        physics:
          model: arm.xml
          frame_skip: 2
          contacts: {{hit: [block, wall]}}
          reset: {{values: {{qvel_slide: 'uniform(0, 3)'}}}}
          observe: [qpos_slide, qvel_slide, qpos_hinge, sim_time, '1 if hit else 0']
        actions:
          continuous: {{ctrl_push: {{low: -1, high: 1}}, ctrl_torque: {{low: -1.0e+30, high: 1.0e+30}}}}
        dynamics: {{let: {{x0: qpos_slide}}}}
        reward: (qpos_slide - x0) / dt + (1 if hit else 0)
        on_fault: {on_fault}
        outcomes:
          far: {{when: abs(qpos_slide) > 2, end: terminate}}
        max_steps: 30
        """),
        encoding="utf-8",
    )
    return path


def assert_same(batch: BatchedVectorEnv, singles: list[VisualEnv], actions: np.ndarray) -> tuple[int, int, int]:
    """Step the batch and the singles with `actions` (NEXT_STEP autoreset on both sides); episode ends, faults, steps touching the wall."""
    pending = [False] * len(singles)
    ends = errors = hits = 0
    for step in actions:
        obs, rewards, terminated, truncated, info = batch.step(step)
        for i, env in enumerate(singles):
            if pending[i]:
                single_obs, _ = env.reset()
                reward, term, trunc, error = 0.0, False, False, None
            else:
                single_obs, reward, term, trunc, single_info = env.step(step[i])
                error = single_info.get("error")
            assert np.array_equal(obs[i], single_obs), (i, obs[i], single_obs)
            assert (rewards[i], terminated[i], truncated[i]) == (reward, term, trunc), i
            assert np.array_equal(batch.lanes[i].data.qpos, env.data.qpos) and np.array_equal(
                batch.lanes[i].data.qvel, env.data.qvel
            )
            assert (info["error"][i] if "error" in info and info["_error"][i] else None) == error
            pending[i] = term or trunc
            ends += term or trunc
            errors += error is not None
            hits += bool(len(single_obs) == 5 and single_obs[4] == 1)
    return ends, errors, hits


@pytest.mark.parametrize("threads", ["1", "2"])
def test_a_batch_steps_every_simulation_at_once_and_each_env_equals_one_env(
    monkeypatch: pytest.MonkeyPatch, threads: str
) -> None:
    """InvertedPendulum, 6 envs, episodes ending and resetting: the batch's MuJoCo step and column reads, never the envs' own."""
    monkeypatch.setenv(THREADS_VARIABLE, threads)
    spec = SPECS / "inverted_pendulum.yaml"
    singles = [VisualEnv(spec, render=False) for _ in range(6)]
    own_steps = []
    stepper = simulation.Simulation.stepper

    def counted(self: simulation.Simulation, controls: list[str], moved: list[str]) -> object:
        advance = stepper(self, controls, moved)
        return lambda values: (own_steps.append(1), advance(values))

    monkeypatch.setattr(simulation.Simulation, "stepper", counted)  # the batch's lanes count their own MuJoCo steps
    batch = BatchedVectorEnv(spec, 6, render=False)
    assert batch._physics is not None and batch._physics.workers == int(threads)
    obs, _ = batch.reset(seed=3)
    for i, env in enumerate(singles):
        assert np.array_equal(obs[i], env.reset(seed=3 + i)[0])
    actions = np.random.default_rng(0).uniform(-3, 3, (60, 6, 1))
    assert assert_same(batch, singles, actions)[0] >= 6  # random pushes topple the pole: episodes end and reset
    assert not own_steps  # no env stepped its own simulation: the batch stepped them all
    batch.close()


@pytest.mark.filterwarnings("ignore:MuJoCo. Nan, Inf or huge value:RuntimeWarning")
@pytest.mark.parametrize("threads", ["1", "2"])
def test_an_env_of_a_batch_that_blows_up_ends_with_its_own_fault_and_the_others_go_on(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, threads: str
) -> None:
    """on_fault: terminate: env 3's simulation blows up (in a worker thread), its episode ends with the message one env gives."""
    monkeypatch.setenv(THREADS_VARIABLE, threads)
    path = arm_spec(tmp_path, "terminate")
    batch = BatchedVectorEnv(path, 4, render=False)
    assert batch._physics is not None and batch._physics.workers == int(threads)
    singles = [VisualEnv(path, render=False) for _ in range(4)]
    obs, _ = batch.reset(seed=5)
    for i, env in enumerate(singles):
        assert np.array_equal(obs[i], env.reset(seed=5 + i)[0])
    actions = np.zeros((25, 4, 2))
    actions[:, :, 0] = np.random.default_rng(1).uniform(-1, 1, (25, 4))
    actions[4, 3, 1] = 1e30  # env 3 only (stepped by the pool's thread with 2 threads), at its fifth step
    ends, errors, hits = assert_same(batch, singles, actions)
    assert errors == 1 and ends >= 1 and hits >= 1, (ends, errors, hits)
    batch.close()


@pytest.mark.filterwarnings("ignore:MuJoCo. Nan, Inf or huge value:RuntimeWarning")
def test_a_blow_up_in_a_batch_raises_the_located_fault_of_that_env(tmp_path: Path) -> None:
    path = arm_spec(tmp_path, "raise")
    batch = BatchedVectorEnv(path, 2, render=False)
    single = VisualEnv(path, render=False)
    batch.reset(seed=0)
    single.reset(seed=1)
    actions = np.array([[0.0, 0.0], [0.0, 1e30]])
    with pytest.raises(StepError) as from_batch:
        batch.step(actions)
    with pytest.raises(StepError) as alone:
        single.step(actions[1])
    assert str(from_batch.value) == f"env 1: {alone.value}" and "blew up" in str(alone.value)  # the batch names its env
    assert from_batch.value.env == 1 and from_batch.value.fault == str(alone.value)
    batch.close()
