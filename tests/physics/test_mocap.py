"""Mocap bodies: a target without a joint, moved by the spec (``mocap_<body>_...``), in the physics and in the picture.

A ball pusher written here: a free ball, and a red goal that is a mocap body
(``<body mocap="true">``). The spec sets the goal at reset and moves it in
``dynamics.update``; MuJoCo's ``mocap_pos`` holds it, its body pose follows, a
batch's env i equals one env, and the drawing shows the goal where MuJoCo has it.
Binding the pose of an object that stands for a body is refused, saying how to move
the body instead.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip("mujoco")

from visualenv.cli import main  # noqa: E402
from visualenv.env.batch import BatchedVectorEnv  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.errors import SpecError, StepError  # noqa: E402

PUSHER = """\
<mujoco>
  <worldbody>
    <light directional="true" pos="0 0 3" dir="0 0 -1"/>
    <geom name="floor" type="plane" size="2 2 0.1" rgba="0.3 0.3 0.3 1"/>
    <body name="ball" pos="0 0 0.1">
      <freejoint name="ball"/>
      <geom name="ball_geom" type="sphere" size="0.1" rgba="0 0 1 1"/>
    </body>
    <body name="goal" mocap="true" pos="0 0 0.05">
      <geom name="goal_geom" type="box" size="0.1 0.1 0.05" rgba="1 0 0 1" contype="0" conaffinity="0"/>
    </body>
    <camera name="top" pos="0 0 3"/>
  </worldbody>
</mujoco>
"""

SPEC = """\
id: Pusher-v0
params: {speed: 0.2}
physics:
  model: pusher.xml
  reset:
    values:
      mocap_goal_x, mocap_goal_y: uniform_disk(0.6)
dynamics:
  update:
    mocap_goal_y: mocap_goal_y + speed
actions: {discrete: [{}]}
reward: -hypot(body_ball_x - mocap_goal_x, body_ball_y - mocap_goal_y)
scene: {world: {color: [0, 0, 0]}}
observation: {camera: top, resolution: [32, 32], color: rgb}
render: {noise: shared}   # Cycles' noise as a batch renders it: a tile equals the env rendered alone
"""


def write(tmp_path: Path, spec: str = SPEC) -> Path:
    (tmp_path / "pusher.xml").write_text(PUSHER, encoding="utf-8")
    path = tmp_path / "pusher.yaml"
    path.write_text(spec, encoding="utf-8")
    return path


def test_inspect_lists_the_mocap_names(tmp_path: Path) -> None:
    (tmp_path / "pusher.xml").write_text(PUSHER, encoding="utf-8")
    result = CliRunner().invoke(main, ["inspect", str(tmp_path / "pusher.xml")])
    assert result.exit_code == 0, result.output
    line = next(t for t in result.output.splitlines() if t.startswith("mocap bodies"))
    assert line.endswith(
        ": mocap_goal_x, mocap_goal_y, mocap_goal_z, mocap_goal_qw, mocap_goal_qx, mocap_goal_qy, mocap_goal_qz"
    ), line
    assert "drawn sites" not in result.output  # the model has none


def test_a_mocap_goal_set_at_reset_and_moved_by_the_update_moves_in_the_physics(tmp_path: Path) -> None:
    """reset.values draws the goal, dynamics.update moves it each step: MuJoCo's mocap_pos and the body's pose follow,
    and every expression reads the names; a batch's env i is env i alone, step after step."""
    path = write(tmp_path)
    env = VisualEnv(path, render=False)
    env.reset(seed=3)
    data = env.data
    goal = data.mocap_pos[0].copy()
    assert 0 < np.hypot(*goal[:2]) <= 0.6 and goal[2] == 0.05  # drawn in the disk; z is the body's own
    assert np.array_equal(data.xpos[2], goal)  # mj_forward after the reset: the body stands where the mocap pose is
    for step in range(1, 4):
        _, reward, *_ = env.step(0)
        assert np.allclose(data.mocap_pos[0], goal + [0, 0.2 * step, 0]) and np.array_equal(
            data.xpos[2], data.mocap_pos[0]
        )
        assert reward == pytest.approx(-np.hypot(*(data.xpos[1][:2] - data.mocap_pos[0][:2])))
    batch = BatchedVectorEnv(path, 3, render=False)
    singles = [VisualEnv(path, render=False) for _ in range(3)]
    try:
        assert batch._physics is not None  # the vectorised step writes the poses: not each lane on its own
        batch.reset(seed=3)
        for i, single in enumerate(singles):
            single.reset(seed=3 + i)
        assert np.allclose(batch.lanes[0].data.mocap_pos, env.data.mocap_pos - [[0, 0.6, 0]])
        for _ in range(3):
            _, rewards, *_ = batch.step(np.zeros(3, dtype=np.int64))
            for i, single in enumerate(singles):
                _, reward, *_ = single.step(0)
                assert np.array_equal(batch.lanes[i].data.mocap_pos, single.data.mocap_pos) and rewards[i] == reward
        assert len({tuple(lane.data.mocap_pos[0]) for lane in batch.lanes}) == 3  # each env drew its own goal
    finally:
        batch.close()
        for single in singles:
            single.close()
    env.close()


def test_a_mocap_pose_that_is_not_finite_is_a_located_fault_alone_and_in_a_batch(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        SPEC.replace("mocap_goal_y + speed", "mocap_goal_y * big * big").replace(
            "actions:", "state: {big: {init: 1e300, observe: false}}\nactions:"
        ),
    )
    env = VisualEnv(path, render=False)
    env.reset(seed=0)
    with pytest.raises(
        StepError, match=r"pusher.yaml:\d+: physics = .*mocap pose set in dynamics.update is not finite: mocap_goal_y="
    ):
        env.step(0)
    env.close()
    batch = BatchedVectorEnv(path, 2, render=False)
    try:
        batch.reset(seed=0)
        with pytest.raises(StepError, match="mocap pose set in dynamics.update is not finite"):
            batch.step(np.zeros(2, dtype=np.int64))
    finally:
        batch.close()


@pytest.mark.parametrize(
    "actor, line, expected",
    [
        (
            "goal_geom: {location: [0, 0, 1]}",
            "17:15",
            "'goal_geom' stands for the MuJoCo body 'goal': binding its location would move the "
            "picture and not the physics. It is a mocap body: set mocap_goal_x, _y, _z",
        ),
        ("'body:goal': {rotation: [0, 0, 1]}", "17:17", "'body:goal' stands for the MuJoCo body 'goal'"),
        ("ball_geom: {location: [0, 0, 1]}", "17:15", "Its joints move it: set qpos_ball_x, qpos_ball_y, qpos_ball_z"),
        (
            "floor: {scale: 2}",
            "17:11",
            "the MuJoCo model's world body (static geoms): binding its scale would move the picture and not "
            "the physics. To move a body that has no joint, put the geoms in a body of their own that is a mocap body",
        ),
        ("top: {location: [0, 0, 2]}", "17:9", "'top' is a camera of the MuJoCo model, which MuJoCo poses every step"),
        (
            "'body:ball': {color: [1, 0, 0]}",
            "17:17",
            "'body:ball' is the frame of the MuJoCo body 'ball': bind its geoms by their names instead (ball_geom)",
        ),
    ],
)
def test_binding_the_pose_of_a_bodys_object_is_refused_saying_how_to_move_the_body(
    tmp_path: Path, actor: str, line: str, expected: str
) -> None:
    path = write(tmp_path, SPEC + f"actors:\n  {actor}\n")
    with pytest.raises(SpecError) as caught:
        VisualEnv(path, render=False)
    assert f"pusher.yaml:{line}: actors." in str(caught.value) and expected in str(caught.value), str(caught.value)


def test_an_object_the_spec_draws_for_a_body_takes_no_pose_binding_but_a_colour(tmp_path: Path) -> None:
    spec = SPEC.replace(
        "scene: {world: {color: [0, 0, 0]}}",
        "scene:\n  objects:\n    goal: {primitive: cube, size: 0.2, material: {color: [1, 0, 0]}}",
    )
    with pytest.raises(SpecError, match=r"actors.goal.location: 'goal' stands for the MuJoCo body 'goal'"):
        VisualEnv(write(tmp_path, spec + "actors: {goal: {location: [0, 0, 1]}}\n"), render=False)
    VisualEnv(
        write(tmp_path, spec + "actors: {goal: {color: [0, 1, 0]}, ball_geom: {color: [1, 1, 0]}}\n"), render=False
    ).close()


def test_a_misspelt_mocap_name_is_a_located_error(tmp_path: Path) -> None:
    for old, new, where in (
        (
            "mocap_goal_y: mocap_goal_y + speed",
            "mocap_gaol_y: 1",
            r"dynamics.update.mocap_gaol_y: 'mocap_gaol_y' "
            r"is not a state variable or a mocap pose \(did you mean 'mocap_goal_y'",
        ),
        (
            "mocap_goal_x, mocap_goal_y:",
            "mocap_goal_x, mocap_gaol_y:",
            r"physics.reset.values.mocap_goal_x, mocap_gaol_y: "
            r"no joint value or mocap pose 'mocap_gaol_y' to set \(did you mean 'mocap_goal_y'",
        ),
    ):
        with pytest.raises(SpecError, match=where):
            VisualEnv(write(tmp_path, SPEC.replace(old, new)), render=False)


def red(image: np.ndarray) -> np.ndarray:
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (r > 80) & (r > g + 50) & (r > b + 50)


@pytest.mark.blender
def test_the_goal_is_drawn_where_its_mocap_pose_puts_it_alone_and_in_a_batch(tmp_path: Path) -> None:
    """The top camera looks down (+x right, +y up in the image): the red goal's pixels sit where reset drew the goal and
    move up the image as dynamics.update moves it; a batch's tiles equal the envs rendered alone."""
    path = write(tmp_path)
    env = VisualEnv(path)
    batch = BatchedVectorEnv(path, 2)
    try:
        obs, _ = env.reset(seed=5)
        tiles, _ = batch.reset(seed=5)
        x, y = env.data.mocap_pos[0][:2]
        rows, cols = np.nonzero(red(obs))
        assert rows.size >= 3
        # 3 m above the goal with MuJoCo's 45 degree fovy: 32 px span 2 * 3 * tan(22.5 deg) = 2.49 m
        assert abs(cols.mean() - (15.5 + x * 32 / 2.485)) < 1.5 and abs(rows.mean() - (15.5 - y * 32 / 2.485)) < 1.5, (
            x,
            y,
            rows.mean(),
            cols.mean(),
        )
        assert (np.abs(tiles[0].astype(int) - obs.astype(int)) <= 8).mean() >= 0.99
        moved, *_ = env.step(0)
        moved_tiles, *_ = batch.step(np.zeros(2, dtype=np.int64))
        assert np.nonzero(red(moved))[0].mean() < rows.mean() - 1.5  # 0.2 m further along +y: higher in the image
        assert (np.abs(moved_tiles[0].astype(int) - moved.astype(int)) <= 8).mean() >= 0.99
        assert not np.array_equal(red(moved_tiles[0]), red(moved_tiles[1]))  # env 1 drew its goal elsewhere
    finally:
        batch.close()
        env.close()


def test_the_pusher_example_places_its_goal_each_episode_and_drifts_it() -> None:
    """examples/mujoco_pusher (linked from docs/physics.md): a new goal per episode, moved by dynamics.update."""
    example = Path(__file__).resolve().parents[2] / "examples" / "mujoco_pusher" / "pusher.yaml"
    env = VisualEnv(example, render=False, params={"drift": 0.5})
    try:
        goals = []
        for seed in (0, 1):
            env.reset(seed=seed)
            goals.append(env.data.mocap_pos[0].copy())
        assert not np.array_equal(goals[0], goals[1]) and all(np.hypot(*g[:2]) <= 0.6 for g in goals)
        env.step(np.zeros(2))
        assert env.data.mocap_pos[0][1] == pytest.approx(goals[1][1] + 0.5 * 0.05)  # drift * dt
    finally:
        env.close()
