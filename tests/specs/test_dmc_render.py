"""The DMC tasks from pixels, rendered by Blender: a geom the reset moves is drawn where it is; tracking cameras follow.

Reacher's reset writes its target geom's model position (``model_geom_pos_target_x/_y``): the
target is drawn there, in one env and in each env of a batch (each env its own target); reacher hard's
also writes its size (``model_geom_size_target_0``, 0.015): drawn at that size. Finger turn's reset moves its
target site and sets its radius: each env of a batch draws its own, as that env alone. Cheetah's
and walker's camera 0 tracks the body's centre of mass: their single envs render through it, so
the body stays in view wherever it runs. (The look, dm_control's lighting, is a later stage: docs/dmc.md.)
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")
pytest.importorskip("bpy")

import visualenv  # noqa: E402
from visualenv.env.batch import BatchedVectorEnv  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402

pytestmark = pytest.mark.blender

DMC = Path(__file__).resolve().parents[2] / "specs" / "dmc"
SIZE = 84
#: reacher's camera 'fixed' looks straight down from 0.75 m (fovy 45 degrees); the target's centre is 0.01 m high
PER_METRE = (SIZE / 2) / ((0.75 - 0.01) * math.tan(math.radians(45 / 2)))


def target_pixel(model) -> tuple[float, float]:
    """Where the camera sees the target's centre: (column, row), x to the right, y up."""
    x, y = model.geom_pos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "target")][:2]
    return (SIZE - 1) / 2 + PER_METRE * x, (SIZE - 1) / 2 - PER_METRE * y


#: the target's radius in each reacher task (dm_control's _BIG_TARGET, _SMALL_TARGET)
RADIUS = {"easy": 0.05, "hard": 0.015}


def with_a_mask(tmp_path: Path, domain: str, task: str, camera: str) -> Path:
    """DMC-<domain>-<task>-v0 with a segmentation camera beside its own (the same camera): where each object is drawn, exactly."""
    text = (DMC / f"{domain}_{task}.yaml").read_text(encoding="utf-8")
    text = text.replace(f"model: assets/{domain}.xml", f"model: {DMC / 'assets' / f'{domain}.xml'}")
    text = text.replace(
        f"observation: {{camera: {camera}, resolution: [84, 84], color: rgb}}",
        f"observation:\n  cameras:\n    eye: {{camera: {camera}, resolution: [84, 84], color: rgb}}\n"
        f"    mask: {{camera: {camera}, resolution: [84, 84], color: segmentation}}",
    )
    path = tmp_path / f"{domain}_mask.yaml"
    path.write_text(text.replace(f"id: DMC-{domain}-{task}-v0", "id: MaskedTask-v0"), encoding="utf-8")
    return path


def reacher_with_a_mask(tmp_path: Path, task: str = "easy") -> Path:
    """DMC-reacher-<task>-v0 with a segmentation camera: where the target is drawn, exactly."""
    return with_a_mask(tmp_path, "reacher", task, "fixed")


@pytest.mark.parametrize("task", RADIUS)
def test_reachers_target_is_drawn_where_the_reset_put_it(tmp_path: Path, task: str) -> None:
    """Where the reset put it, and as large as it made it: a disc of the target's radius seen from above."""
    env = VisualEnv(reacher_with_a_mask(tmp_path, task))
    disc = math.pi * (RADIUS[task] * PER_METRE) ** 2  # about 147 pixels (easy) and 13 (hard)
    try:
        target = env.segmentation_ids["geom:target"]  # a geom the reset moves is drawn on a body of its own
        seen = []
        for seed in (0, 1, 2):
            obs, _ = env.reset(seed=seed)
            mask = obs["mask"][..., 0] == target
            rows, columns = np.nonzero(mask)
            column, row = target_pixel(env.model)
            assert 0.6 * disc <= mask.sum() <= 1.1 * disc, (mask.sum(), disc)  # the arm may hide some of it
            assert abs(columns.mean() - column) < 1.0 and abs(rows.mean() - row) < 1.0, (
                seed,
                columns.mean(),
                rows.mean(),
                column,
                row,
            )
            eye = obs["eye"].astype(int)
            redness = eye[..., 0] - eye[..., 2]  # the target's red in the rgb frame, where the floor around it is blue
            assert redness[mask].mean() > 10 and redness[mask].mean() > redness[~mask].mean() + 20, (
                redness[mask].mean(),
                redness[~mask].mean(),
            )
            seen.append((column, row))
        assert len({(round(c), round(r)) for c, r in seen}) == 3  # three episodes, three places
    finally:
        env.close()


@pytest.mark.parametrize("task", RADIUS)
def test_each_env_of_a_batch_draws_its_own_target(tmp_path: Path, task: str) -> None:
    """Tile i's target is where env i's reset put it, and its mask is env i's rendered alone, over a few steps (hard's
    target as small as its reset made it: drawn scaled in each env's tile)."""
    path = reacher_with_a_mask(tmp_path, task)
    batch = BatchedVectorEnv(path, 3, action_repeat=1)
    singles = [VisualEnv(path, action_repeat=1) for _ in range(3)]
    try:
        obs, _ = batch.reset(seed=5)
        target = batch.segmentation_ids["geom:target"]
        places = set()
        actions = np.zeros((3, 2))
        for step in range(3):
            for i, env in enumerate(singles):
                alone = env.reset(seed=5 + i)[0] if step == 0 else env.step(actions[i])[0]
                mask = obs["mask"][i][..., 0] == target
                rows, columns = np.nonzero(mask)
                column, row = target_pixel(batch.lanes[i].model)
                assert abs(columns.mean() - column) < 1.0 and abs(rows.mean() - row) < 1.0, (
                    step,
                    i,
                    columns.mean(),
                    rows.mean(),
                    column,
                    row,
                )
                assert (obs["mask"][i] == alone["mask"]).mean() >= 0.99, (step, i)
                places.add((round(column), round(row)))
            actions = np.random.default_rng(step).uniform(-1, 1, size=(3, 2))
            obs, *_ = batch.step(actions)
        assert len(places) == 3  # each env its own target, kept while the arms move
    finally:
        batch.close()
        for env in singles:
            env.close()


@pytest.mark.parametrize("ident", ["DMC-finger-turn_easy-v0", "DMC-finger-turn_hard-v0"])
def test_each_env_of_a_finger_turn_batch_draws_its_own_target(ident: str) -> None:
    """Finger turn's reset moves its target site and sets its radius (a site of the world body, which segmentation
    counts as the floor's): tile i is env i's frame alone, its own target where and as large as env i's, though each
    env's target is elsewhere. (One env's target against MuJoCo's: tests/specs/test_dmc_drawn.py.)"""
    batch = visualenv.make_vec(ident, 2, batched=True, action_repeat=1)
    try:
        tiles, _ = batch.reset(seed=2)
        assert not np.array_equal(batch.unwrapped.lanes[0].model.site_pos, batch.unwrapped.lanes[1].model.site_pos)
        for i in range(2):
            env = visualenv.make(ident, action_repeat=1)
            try:
                alone = env.reset(seed=2 + i)[0].astype(int)
            finally:
                env.close()
            difference = np.abs(tiles[i].astype(int) - alone)
            assert (difference > 8).mean() < 0.001, (i, (difference > 8).sum(), difference.mean())
    finally:
        batch.close()


def body_column(frame: np.ndarray) -> tuple[float, int]:
    """The mean column of the body's pixels (the 'self' material's tan: red well over blue) and how many there are."""
    rgb = frame.astype(int)
    body = (rgb[..., 0] > rgb[..., 2] + 40) & (rgb[..., 0] > 100)
    return (float(np.nonzero(body)[1].mean()) if body.any() else -1.0), int(body.sum())


#: the joint moved, its qpos entry and the world axis: the planar bodies move along their root's x slide (across the side
#: camera's view), the humanoid along its free joint's y (across its camera 'back', which looks along x), the quadruped
#: along its free joint's x (across its camera 2, 'y', beside it)
MOVED = {
    "DMC-cheetah-run-v0": ("rootx", 0, 0),
    "DMC-walker-walk-v0": ("rootx", 0, 0),
    "DMC-hopper-hop-v0": ("rootx", 0, 0),
    "DMC-humanoid-walk-v0": ("root", 1, 1),
    "DMC-quadruped-walk-v0": ("root", 0, 0),
}


@pytest.mark.parametrize("ident", MOVED)
def test_the_tracking_camera_keeps_the_body_in_view(ident: str) -> None:
    """Moved 3 m along the floor (beyond a fixed camera's view), the body is drawn where it was in the frame: the camera followed."""
    env = visualenv.make(ident, action_repeat=1)
    try:
        obs, _ = env.reset(seed=0)
        column, count = body_column(obs)
        assert count > 40, count
        data, model = env.unwrapped.data, env.unwrapped.model
        joint, entry, axis = MOVED[ident]
        data.qpos[model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)] + entry] += 3.0
        mujoco.mj_forward(model, data)
        moved, _, _, _, _ = env.step(np.zeros(env.action_space.shape))
        assert env.unwrapped.data.subtree_com[1][axis] > 2.5  # the body's centre of mass is 3 m further
        column_after, count_after = body_column(moved)
        assert abs(column_after - column) < 4 and count_after > 0.7 * count, (column, count, column_after, count_after)
    finally:
        env.close()


def test_a_spot_lit_batch_past_four_envs_is_lit_as_each_env_alone() -> None:
    """Cartpole's spot light, one per env: each env's copy of the scene is lit only by its own spot (light linking).
    Shared by Cycles' light tree, the spots of other envs took some of each pixel's one sample from 5 or 6 envs up:
    at 8 envs the worst tile was 11 levels off on average (results/benchmarks/batch-lights.md)."""
    n = 6
    batch = visualenv.make_vec("DMC-cartpole-swingup-v0", n, batched=True)
    try:
        tiles, _ = batch.reset(seed=3)
        renderer = batch.unwrapped.renderer
        lights = [copy.objects["light"] for copy in renderer._copies]
        assert len({light.as_pointer() for light in lights}) == n  # a spot per env ...
        for k, light in enumerate(lights):  # ... lighting and shadowing only its own copy's objects
            receivers = set(light.light_linking.receiver_collection.objects)
            assert receivers and light.light_linking.blocker_collection == light.light_linking.receiver_collection
            assert receivers == {o for o in renderer._copies[k].objects.values() if o.type != "LIGHT"}, k
        for k in range(n):
            env = visualenv.make("DMC-cartpole-swingup-v0")
            try:
                alone = env.reset(seed=3 + k)[0].astype(int)
            finally:
                env.close()
            difference = np.abs(tiles[k].astype(int) - alone)
            assert difference.mean() < 0.2 and (difference <= 8).mean() > 0.999, (
                k,
                difference.mean(),
                (difference > 8).sum(),
            )
        assert not np.array_equal(tiles[0], tiles[1])  # each tile its own env's cart and pole
    finally:
        batch.close()
