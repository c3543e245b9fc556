"""`visualenv inspect model.xml` and `visualenv init model.xml`, on MJCF models this project did not write.

Gymnasium's own assets (ant, humanoid, hopper, pusher, swimmer, walker): the
starter spec compiles, resets and steps as written with every actuator driven;
one renders. Bad files are located errors, never tracebacks.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip("mujoco")
#: these are Gymnasium's own files: its half_cheetah.xml has settotalmass, which MuJoCo 3 deprecates (MuJoCo's warnings are Python warnings here)
pytestmark = pytest.mark.filterwarnings("ignore:MuJoCo. compiler attribute:RuntimeWarning")

from visualenv.cli import main  # noqa: E402
from visualenv.env.visual_env import VisualEnv  # noqa: E402
from visualenv.physics.model import resolve_model_path  # noqa: E402

ASSETS = resolve_model_path("package:gymnasium.envs.mujoco/assets/ant.xml", Path(".")).parent
MODELS = ["ant", "humanoid", "hopper", "pusher_v5", "swimmer", "walker2d_v5"]


def test_inspect_lists_the_names() -> None:
    result = CliRunner().invoke(main, ["inspect", str(ASSETS / "half_cheetah.xml")])
    assert result.exit_code == 0, result.output
    text = result.output
    assert "6 actuators" in text and "actuator bthigh: ctrl_bthigh in [-1, 1]" in text
    for name in (
        "qpos_rootx",
        "qvel_ffoot",
        "body_torso_z",
        "body_torso_qw",
        "geoms (for contacts): floor, torso",
        "sim_time",
        "drawn geoms: floor (plane), torso (capsule)",
        "cameras (observation.camera): track",
        "lights: light0",
    ):
        assert name in text, name


@pytest.mark.parametrize("model", MODELS)
def test_init_writes_a_spec_that_steps(tmp_path: Path, model: str) -> None:
    out = tmp_path / "spec.yaml"
    result = CliRunner().invoke(main, ["init", str(ASSETS / f"{model}.xml"), "-o", str(out)])
    assert result.exit_code == 0, result.output
    text = out.read_text(encoding="utf-8")
    assert "# Names expressions can read:" in text and "qpos_" in text
    env = VisualEnv(out, render=False)
    nu = env.unwrapped.model.nu
    assert env.action_space.shape == (nu,)
    env.reset(seed=0)
    for _ in range(20):
        obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
    assert np.isfinite(obs).all() and reward == 0.0 and not terminated
    assert np.any(env.unwrapped.data.ctrl != 0)


@pytest.mark.blender
def test_an_init_spec_renders_the_model(tmp_path: Path) -> None:
    out = tmp_path / "spec.yaml"
    CliRunner().invoke(main, ["init", str(ASSETS / "hopper.xml"), "-o", str(out)])
    out.write_text(
        out.read_text(encoding="utf-8").replace("resolution: [84, 84]", "resolution: [24, 24]"), encoding="utf-8"
    )
    env = VisualEnv(out)
    try:
        obs, _ = env.reset(seed=0)
        # the hopper (light material) stands in the middle of the frame of its own `track` camera, which the starter observes through
        middle, edge = obs[4:20, 9:15].astype(int).sum(axis=2), obs[4:20, :3].astype(int).sum(axis=2)
        assert obs.shape == (24, 24, 3) and np.abs(middle - edge.mean()).max() > 60
    finally:
        env.close()


@pytest.mark.parametrize(
    "text, expected",
    [
        ("<mujoco><worldbody><geom type='sphere' size='1'/></worldbody>", "XML parse error"),
        ("<mujoco><worldbody><joint name='j'/></worldbody></mujoco>", "MuJoCo cannot load"),
    ],
)
def test_a_bad_model_is_a_clear_error(tmp_path: Path, text: str, expected: str) -> None:
    bad = tmp_path / "bad.xml"
    bad.write_text(text, encoding="utf-8")
    for command in (["inspect", str(bad)], ["init", str(bad), "-o", str(tmp_path / "s.yaml")]):
        result = CliRunner().invoke(main, command)
        assert result.exit_code != 0 and expected in result.output and "Traceback" not in result.output, result.output


CAMERAS = """\
<mujoco>
  <worldbody>
    <light pos="0 0 3"/>
    <body name="box" pos="0 0 0.5"><freejoint/><geom type="box" size="0.1 0.1 0.1"/></body>
    <camera name="side" pos="0 -2 0.5" xyaxes="1 0 0 0 0 1"/>
    <camera name="top" pos="0 0 3"/>
  </worldbody>
</mujoco>
"""


def test_init_observes_through_the_models_first_camera(tmp_path: Path) -> None:
    """A model with cameras: the starter spec observes through the first, says so, and adds no camera of its own."""
    (tmp_path / "m.xml").write_text(CAMERAS, encoding="utf-8")
    out = tmp_path / "spec.yaml"
    result = CliRunner().invoke(main, ["init", str(tmp_path / "m.xml"), "-o", str(out)])
    assert result.exit_code == 0, result.output
    text = out.read_text(encoding="utf-8")
    assert "observation: {camera: side, resolution: [84, 84], color: rgb}" in text
    assert "# the model's first camera, side (" in text and "its others: top" in text
    assert "Camera:" not in text and "perspective" not in text
    env = VisualEnv(out, render=False)  # compiles: the camera is the model's
    assert env.program.spec.observation.camera == "side"
    env.close()
    (tmp_path / "bare.xml").write_text(
        CAMERAS.replace('<camera name="side" pos="0 -2 0.5" xyaxes="1 0 0 0 0 1"/>', "").replace(
            '<camera name="top" pos="0 0 3"/>', ""
        ),
        encoding="utf-8",
    )
    CliRunner().invoke(main, ["init", str(tmp_path / "bare.xml"), "-o", str(tmp_path / "bare.yaml")])
    assert "observation: {camera: Camera," in (tmp_path / "bare.yaml").read_text(
        encoding="utf-8"
    )  # no camera in the model: the starter's own
