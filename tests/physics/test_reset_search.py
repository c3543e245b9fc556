"""A physics reset's search (values stepped from the last try until a condition holds), ``random_quaternion()`` and the
actuators' ``act_`` names: what dm_control's quadruped reset and observation need, on small models written here.

dm_control's quadruped raises its body 1 cm at a time until nothing touches (``_find_non_contacting_height``): the
reference here is that loop written with MuJoCo's calls. The quadruped ids themselves are compared with dm_control in
tests/specs/test_dmc_tasks.py.
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

#: a box on a free joint over a floor, a ball on a slide, a hinge driven by a filter actuator (an activation state)
MODEL = """\
<mujoco model="search">
  <option timestep="0.01"/>
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="box" pos="0 0 1">
      <freejoint name="root"/>
      <geom name="box_geom" type="box" size="0.3 0.2 0.1"/>
    </body>
    <body name="ball" pos="3 0 2">
      <joint name="slide" type="slide" axis="1 0 0"/>
      <geom name="ball_geom" type="sphere" size="0.1" contype="0" conaffinity="0"/>
    </body>
    <body name="arm" pos="-3 0 2">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom name="arm_geom" type="capsule" fromto="0 0 0 0 0 -0.5" size="0.05" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator>
    <general name="filtered" joint="hinge" dyntype="filter" dynprm="0.1" ctrllimited="true" ctrlrange="-1 1"/>
  </actuator>
</mujoco>
"""

#: the quadruped's reset: a random orientation, the body at the origin embedded in the floor, raised until nothing touches
RAISE = """\
reset:
  values:
    qpos_root_qw, qpos_root_qx, qpos_root_qy, qpos_root_qz: random_quaternion()
    qpos_root_x: 0
    qpos_root_y: 0
    qpos_root_z: 0
  search:
    until: ncon == 0
    step: {qpos_root_z: qpos_root_z + 0.01}
"""


def write(tmp_path: Path, extra: str, convention: str = "dm_control") -> Path:
    """The spec: `extra` (dedented) inside the physics section."""
    (tmp_path / "search.xml").write_text(MODEL, encoding="utf-8")
    path = tmp_path / "spec.yaml"
    body = textwrap.indent(textwrap.dedent(extra), "  ")
    path.write_text(
        f"id: Search-v0\nphysics:\n  model: search.xml\n  convention: {convention}\n{body}", encoding="utf-8"
    )
    return path


def raised(model, seed: int) -> tuple[np.ndarray, int]:
    """dm_control's quadruped reset on `model`: its orientation draw and _find_non_contacting_height; the qpos and tries."""
    orientation = np.random.RandomState(seed).randn(4)
    orientation /= np.linalg.norm(orientation)
    data = mujoco.MjData(model)
    z, tries = 0.0, 0
    while True:
        mujoco.mj_resetData(model, data)
        data.qpos[:3] = 0.0, 0.0, z
        data.qpos[3:7] = orientation
        mujoco.mj_forward(model, data)
        tries += 1
        if data.ncon == 0:
            return data.qpos.copy(), tries
        z += 0.01  # a sum, not 0.01 * tries: its roundings are the reset's


def test_a_search_raises_a_body_until_nothing_touches_as_dm_controls_quadruped(tmp_path: Path) -> None:
    env = VisualEnv(write(tmp_path, RAISE), render=False)
    tries = set()
    for seed in range(5):
        env.reset(seed=seed)
        qpos, n = raised(env.model, seed)
        np.testing.assert_array_equal(env.data.qpos, qpos, err_msg=f"seed {seed}")
        assert env.data.ncon == 0
        tries.add(n)
    assert min(tries) > 5 and len(tries) > 1, tries  # the box starts in the floor: each orientation needs its own tries


def test_each_try_goes_on_from_the_last(tmp_path: Path) -> None:
    """Where a redraw starts every try from the reset's values, a search steps them: eight steps of 0.1, summed."""
    extra = """\
    reset:
      values: {qpos_slide: 0}
      search: {until: qpos_slide > 0.75, step: {qpos_slide: qpos_slide + 0.1}}
    observe: [qpos_slide]
    """
    obs, _ = VisualEnv(write(tmp_path, extra), render=False).reset(seed=0)
    assert obs[0] == 0.1 + 0.1 + 0.1 + 0.1 + 0.1 + 0.1 + 0.1 + 0.1 == 0.7999999999999999  # not 8 * 0.1


def test_a_batch_searches_as_its_envs_do(tmp_path: Path) -> None:
    path = write(tmp_path, RAISE + "observe: [qpos_root_z, qpos_root_qw, ncon]\n")
    batch = BatchedVectorEnv(path, 3, render=False)
    obs, _ = batch.reset(seed=4)
    for i in range(3):
        np.testing.assert_array_equal(obs[i], VisualEnv(path, render=False).reset(seed=4 + i)[0])
    batch.close()


def test_a_search_that_never_meets_its_condition_is_a_located_fault(tmp_path: Path) -> None:
    extra = """\
    reset:
      search:
        until: qpos_slide > 1
        step: {qpos_slide: qpos_slide + 0.1}
        attempts: 5
    """
    path = write(tmp_path, extra)
    with pytest.raises(StepError) as caught:
        VisualEnv(path, render=False).reset(seed=0)
    message = str(caught.value)
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if "until:" in text)
    assert f"spec.yaml:{line}: physics.reset.search.until = 'qpos_slide > 1'" in message
    assert "none of 5 tries met the condition (physics.reset.search.attempts)" in message


@pytest.mark.parametrize(
    "search, where",
    [
        ("{until: ncon == 0, step: {qpos_slide: 1}, attempts: 0}", "physics.reset.search.attempts"),
        ("{until: ncon == 0, step: {qpos_slid: 1}}", "no joint value 'qpos_slid' to set (did you mean 'qpos_slide'"),
        ("{until: ncon + 1, step: {qpos_slide: 1}}", "physics.reset.search.until"),
        ("{until: ncon == 0, step: {}}", "physics.reset.search.step"),
        ("{until: ncon == 0}", "physics.reset.search"),
    ],
)
def test_a_bad_search_is_a_located_error(tmp_path: Path, search: str, where: str) -> None:
    path = write(tmp_path, f"reset:\n  search: {search}\n")
    with pytest.raises(SpecError) as caught:
        compile_spec(load_spec(path))
    assert re.search(rf"spec\.yaml:6:\d+: [^\n]*{re.escape(where)}", str(caught.value)), str(caught.value)


@pytest.mark.parametrize("convention", ["dm_control", "gymnasium"])
def test_random_quaternion_draws_four_normals_over_their_norm(tmp_path: Path, convention: str) -> None:
    """dm_control's RandomState(seed).randn(4), or Gymnasium's generator's standard_normal(4), divided by its norm."""
    extra = f"{RAISE}observe: [qpos_root_qw, qpos_root_qx, qpos_root_qy, qpos_root_qz]\n"
    obs, _ = VisualEnv(write(tmp_path, extra, convention), render=False).reset(seed=3)
    if convention == "dm_control":
        stream = np.random.RandomState(3)
        drawn = stream.randn(4)
    else:
        generator = np.random.default_rng(3)  # Gymnasium's np_random for seed 3
        drawn = generator.standard_normal(4)
    np.testing.assert_array_equal(obs[:4], drawn / np.linalg.norm(drawn))
    assert abs(np.linalg.norm(obs[:4]) - 1.0) < 1e-15


def test_act_names_read_an_actuators_activation(tmp_path: Path) -> None:
    env = VisualEnv(write(tmp_path, "observe: [act_filtered, ctrl_filtered]\n"), render=False)
    obs, _ = env.reset(seed=0)
    assert obs.tolist() == [0.0, 0.0]
    for _ in range(3):
        obs, *_ = env.step(np.array([1.0]))
    assert 0.0 < obs[0] == env.data.act[0] < 1.0 and obs[1] == 1.0
