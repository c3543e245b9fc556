"""`visualenv view` over plain HTTP, as a user starts it: keys step the rendered env, a saved edit rebuilds it (a broken
one shows its located error while the last good env goes on), and Ctrl-C stops it with exit code 0.

The same in a real browser: test_browser.py; the rules of the session without Blender: test_parts.py.
"""

from __future__ import annotations

import io
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.fixtures.viewer import ViewerProcess

pytestmark = pytest.mark.blender

REPO = Path(__file__).resolve().parents[2]
CARTPOLE = (REPO / "specs" / "visual_cartpole.yaml").read_text()
RED_CART = "Cart:   {primitive: cube, size: [0.5, 0.3, 0.25], material: {color: [0.8, 0.2, 0.2]}}"
WHITE_CART = RED_CART.replace("[0.8, 0.2, 0.2]", "[1.0, 1.0, 1.0]")


@pytest.fixture(scope="module")
def viewer(tmp_path_factory):
    """A copy of the bundled CartPole (the tests edit it) in `visualenv view`, without the high-resolution view."""
    spec = tmp_path_factory.mktemp("viewer") / "cartpole.yaml"
    spec.write_text(CARTPOLE)
    with ViewerProcess([str(spec), "--view", "off"]) as process:
        process.spec = spec
        yield process


def observation(viewer: ViewerProcess) -> np.ndarray:
    with urllib.request.urlopen(viewer.url + "picture/observation", timeout=30) as response:
        return np.asarray(Image.open(io.BytesIO(response.read())))


def reset(viewer: ViewerProcess, seed: int) -> dict:
    """The page's reset with `seed`, and the state once it is done."""
    episode = viewer.state()["values"]["episode"]
    viewer.send({"type": "reset", "seed": seed})
    return viewer.wait_for(lambda s: s["values"]["episode"] > episode and s["values"]["step"] == 0, 60, "a reset")


def test_keys_step_the_env_and_the_page_shows_each_observation(viewer):
    with urllib.request.urlopen(viewer.url, timeout=30) as response:
        assert b"EventSource" in response.read()
    state = reset(viewer, seed=0)
    assert state["values"]["status"] == "waiting for a key"
    assert {k["text"]: k["keys"] for k in state["values"]["controls"]["keys"]} == {
        "action 0: force = -force_mag": ["ArrowLeft", "0"],
        "action 1: force = force_mag": ["ArrowRight", "1"],
    }
    before = observation(viewer)
    assert before.shape == (100, 100) and before.std() > 0
    for _ in range(6):  # six taps of the right arrow: six steps (the pole tilts 0.11 rad)
        viewer.send({"type": "key", "key": "ArrowRight", "down": True})
        viewer.send({"type": "key", "key": "ArrowRight", "down": False})
    state = viewer.wait_for(lambda s: s["values"]["step"] == 6, 60, "six steps")
    assert state["values"]["action"] == "1: force = force_mag" and state["values"]["state"]["x_dot"] > 0.8
    after = observation(viewer)
    assert (np.abs(after.astype(int) - before) > 16).sum() >= 10, "the cart and pole did not move in the observation"


def test_a_saved_edit_rebuilds_the_env_and_a_broken_one_shows_its_located_error(viewer):
    spec: Path = viewer.spec
    builds = reset(viewer, seed=0)["values"]["builds"]  # a rebuild starts the episode of the same seed: the same state
    before = observation(viewer)
    spec.write_text(CARTPOLE.replace(RED_CART, WHITE_CART))
    viewer.wait_for(lambda s: s["values"]["builds"] == builds + 1, 120, "a rebuild")
    after = observation(viewer)
    assert ((after.astype(int) - before) > 40).sum() >= 15, "the white cart is not brighter than the red one"
    assert ((after.astype(int) - before) < -8).sum() == 0, "more than the cart's colour changed"
    broken = CARTPOLE.replace("reward: 1.0", "reward: 1.0 + speedd")
    spec.write_text(broken)
    line = broken.splitlines().index("reward: 1.0 + speedd") + 1
    state = viewer.wait_for(lambda s: s["values"]["error"], 60, "the error of the broken spec")
    assert state["values"]["error"].startswith(f"{spec}:{line}:15: reward: unknown name 'speedd'"), state["values"][
        "error"
    ]
    step = state["values"]["step"]
    viewer.send({"type": "key", "key": "ArrowLeft", "down": True})
    viewer.send({"type": "key", "key": "ArrowLeft", "down": False})
    viewer.wait_for(lambda s: s["values"]["step"] == step + 1, 60, "a step of the last good env")
    spec.write_text(CARTPOLE)
    state = viewer.wait_for(lambda s: s["values"]["builds"] == builds + 2, 120, "the fixed spec's build")
    assert state["values"]["error"] is None


def test_ctrl_c_stops_the_viewer_with_exit_code_0():
    with ViewerProcess(["VisualCartPole-v0", "--view", "off"]) as process:
        process.wait_for(lambda s: s["values"]["builds"] == 1, 60, "the build")
        code = process.stop()
    output = process.text()
    assert code == 0, output
    assert "stopped" in output and "Traceback" not in output and "KeyboardInterrupt" not in output
