"""Every mesh of a MuJoCo scene is drawn as an instance (``scene/mjcf.keep_instanced``): each gets a second user that
no camera sees, so Cycles keeps its acceleration structure between steps rather than rebuild it.

Real renders: a cheetah episode rendered with the second users and again, from the same seed and actions, with them
hidden (each mesh then drawn as Cycles draws a mesh used once) shows the same frames but for a few edge pixels, and
the frames change as the cheetah runs (the test would see a second user that a camera could see). A batch of one is
drawn so too, by one env's renderer, and shows the env's own frames.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

import visualenv  # noqa: E402

pytestmark = pytest.mark.blender


def _episode(env, actions: np.ndarray) -> np.ndarray:
    obs, _ = env.reset(seed=3)
    frames = [obs]
    for action in actions:
        obs, *_ = env.step(action)
        frames.append(obs)
    return np.array(frames, dtype=np.int16)


def test_each_mesh_of_a_mujoco_scene_has_a_second_user_that_changes_no_frame() -> None:
    from visualenv.render.blender.scene.mjcf import SECOND_USER

    env = visualenv.make("DMC-cheetah-run-v0", max_episode_steps=20)
    try:
        scene = env.unwrapped.renderer.scene
        meshes = [o for o in scene.objects if o.type == "MESH" and not o.hide_render]
        seconds = [o for o in meshes if o.name.endswith(SECOND_USER)]
        drawn = [o for o in meshes if not o.name.endswith(SECOND_USER)]
        assert drawn and len(seconds) == len(drawn)
        assert all(o.data.users >= 2 for o in drawn)
        assert all(tuple(o.scale) == (0.0, 0.0, 0.0) and not o.visible_camera for o in seconds)
        actions = np.random.default_rng(0).uniform(-1, 1, (8, *env.action_space.shape)).astype(np.float32)
        instanced = _episode(env, actions)
        for second in seconds:
            second.hide_render = True
        used_once = _episode(env, actions)
    finally:
        env.close()
    assert np.abs(instanced[0] - instanced[-1]).mean() > 1.0  # the cheetah moved in view
    difference = np.abs(instanced - used_once)
    assert difference.mean() < 0.01 and (difference > 1).mean() < 1e-4, (difference.mean(), difference.max())


def test_a_batch_of_one_draws_its_env_as_one_env_does() -> None:
    """A batch of one is drawn by one env's renderer, every mesh with its second user (a batch's instancers would draw
    each body by one instance of a mesh used once, which Cycles rebuilds at every step): the env's own frames, bit for
    bit."""
    from visualenv.render.blender.batch.renderer import BatchedBlenderRenderer
    from visualenv.render.blender.scene.mjcf import SECOND_USER

    batch = visualenv.make_vec("DMC-cheetah-run-v0", 1, batched=True)
    alone = visualenv.make("DMC-cheetah-run-v0")
    try:
        tiles, _ = batch.reset(seed=4)
        renderer = batch.unwrapped.renderer
        assert not isinstance(renderer, BatchedBlenderRenderer)
        assert any(o.name.endswith(SECOND_USER) for o in renderer.scene.objects)
        frames = [alone.reset(seed=4)[0]]
        assert np.array_equal(tiles[0], frames[0])
        for action in np.random.default_rng(1).uniform(-1, 1, (6, *alone.action_space.shape)).astype(np.float32):
            frames.append(alone.step(action)[0])
            assert np.array_equal(batch.step(action[None])[0][0], frames[-1])
        assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 1.0  # the cheetah moved in view
    finally:
        batch.close()
        alone.close()
