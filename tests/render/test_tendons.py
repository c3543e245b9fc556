"""A model's tendons are drawn where MuJoCo draws them: ball_in_cup's string hangs below the cup while slack."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

import visualenv  # noqa: E402
from visualenv.physics.tendons import tendon_path  # noqa: E402

pytestmark = pytest.mark.blender

ID = "DMC-ball_in_cup-catch-v0"


def test_the_string_is_drawn_along_its_hanging_path() -> None:
    env = visualenv.make(ID)
    try:
        shown, _ = env.reset(seed=0)
        unwrapped = env.unwrapped
        model, data = unwrapped.model, unwrapped.data
        (string,) = unwrapped.program.render_plan().physics.tendons
        sites = data.site_xpos[model.wrap_objid[:2]].copy()
        path = tendon_path(string, sites)
        assert len(path) == 29, "the string is slack at this reset: it hangs"
        for k in range(string.segments):
            unwrapped.renderer.object(f"{string.name}:{k}").hide_render = True
        hidden, _ = env.reset(seed=0)  # the same state, drawn without the string
        cam_pos, cam_mat, fovy = data.cam_xpos[0].copy(), data.cam_xmat[0].reshape(3, 3).copy(), model.cam_fovy[0]
    finally:
        env.close()
    changed = np.argwhere(np.abs(shown.astype(int) - hidden).max(axis=2) > 10)
    assert len(changed) >= 8, "the string shows"
    size = shown.shape[0]
    focal = (size / 2) / np.tan(np.radians(fovy) / 2)

    def pixel(point: np.ndarray) -> np.ndarray:
        """(row, column) of a world point through MuJoCo's camera (it looks down its -z, y up)."""
        x, y, z = cam_mat.T @ (point - cam_pos)
        return np.array([size / 2 - focal * y / -z, size / 2 + focal * x / -z])

    drawn = np.array([pixel(p) for p in np.linspace(path[:-1], path[1:], 20).reshape(-1, 3)])
    distance = np.min(np.linalg.norm(changed[:, None, :] + 0.5 - drawn[None], axis=2), axis=1)
    assert distance.max() <= 1.5, "every changed pixel lies on the string's projected path"
    cup = pixel(sites[1])[0]
    assert (changed[:, 0] > cup + 3).any(), "it hangs below the cup, as MuJoCo draws it"
