"""`visualenv build` / `preview` end to end, loading a build folder, and domain randomization (real renders)."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

import visualenv
from visualenv.cli import main
from visualenv.errors import SpecError

pytestmark = pytest.mark.blender

ROOT = Path(__file__).resolve().parents[2]


def test_build_writes_env_json_blend_and_preview_then_loads(tmp_path):
    result = CliRunner().invoke(main, ["build", str(ROOT / "specs" / "visual_cartpole.yaml"), "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "VisualCartPole-v0"
    record = json.loads((folder / "env.json").read_text())
    assert record["id"] == "VisualCartPole-v0" and len(record["sha256"]) == 64
    assert record["versions"]["blender"].startswith("5.0") and record["spec"]["max_steps"] == 200
    assert (folder / "scene.blend").read_bytes()[:7] == b"BLENDER"
    preview = np.asarray(Image.open(folder / "preview.png"))
    assert preview.shape[1] > preview.shape[0]  # observation beside the view
    assert "observation (reset" in result.output  # the text sketch of the observation

    env = visualenv.make(folder)
    obs, _ = env.reset(seed=1)
    assert obs.shape == (100, 100, 1) and obs.dtype == np.uint8
    env.close()


def test_a_broken_build_record_is_named(tmp_path):
    for i, (text, message) in enumerate(
        [
            ("{bad", "not a build record of `visualenv build` (JSONDecodeError"),
            ('{"id": "X"}', "(KeyError: 'source')"),
            ('{"source": "/nowhere/gone.yaml"}', "source: the spec it was built from is gone: /nowhere/gone.yaml"),
        ]
    ):
        folder = tmp_path / str(i)
        folder.mkdir()
        (folder / "env.json").write_text(text)
        with pytest.raises(SpecError, match="env.json") as info:
            visualenv.make(folder)
        assert message in str(info.value)


@pytest.mark.slow
def test_preview_writes_frames_of_a_random_episode(tmp_path):
    result = CliRunner().invoke(main, ["preview", "Hover2D-v0", "--out", str(tmp_path), "--steps", "3"])
    assert result.exit_code == 0, result.output
    frames = sorted(tmp_path.glob("frame_*.png"))
    assert len(frames) == 4
    images = [np.asarray(Image.open(f)).astype(int) for f in frames]
    assert any(np.abs(images[0] - im).mean() > 0.1 for im in images[1:])  # the camera moved


def test_gpu_request_falls_back_to_cpu_with_a_message(tmp_path, monkeypatch):
    from visualenv.render.blender.runtime import settings

    if settings.detect_gpu():
        pytest.skip("Blender finds a GPU here: nothing to fall back from")
    monkeypatch.setattr(settings, "_warned", set())  # said once per process: say it again here
    with pytest.warns(
        RuntimeWarning,
        match="render.device is 'gpu' but Blender found no CUDA/OptiX/HIP/Metal/oneAPI device: rendering on the CPU",
    ):
        result = CliRunner().invoke(main, ["build", "Goalie-v0", "--out", str(tmp_path), "--device", "gpu", "--quiet"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "Goalie-v0" / "preview.png").exists()
    env = visualenv.make("Goalie-v0", device="gpu")
    try:
        env.reset(seed=0)
        assert env.unwrapped.renderer.scene.cycles.device == "CPU"
    finally:
        env.close()


def box_colour(obs: np.ndarray) -> np.ndarray:
    """Mean colour of the cube: the centre of the 84x84 view (the camera looks at it)."""
    return obs[38:46, 38:46].reshape(-1, 3).mean(axis=0)


def test_domain_randomization_changes_the_scene_per_episode():
    env = visualenv.make(ROOT / "examples" / "domain_randomization.yaml")
    try:
        a, info_a = env.reset(seed=0)
        b, info_b = env.reset(seed=1)
        a_again, _ = env.reset(seed=0)
    finally:
        env.close()
    np.testing.assert_array_equal(a, a_again)  # same seed, same scene
    assert info_a["state"]["red"] != info_b["state"]["red"]
    # the cube's colour follows the drawn red/green values
    ca, cb = box_colour(a), box_colour(b)
    assert np.abs(ca - cb).max() > 10
    redder = (
        ca
        if info_a["state"]["red"] - info_a["state"]["green"] > info_b["state"]["red"] - info_b["state"]["green"]
        else cb
    )
    other = cb if redder is ca else ca
    assert (redder[0] - redder[1]) > (other[0] - other[1])


def test_play_view_override_changes_preset_and_size_keeping_aspect():
    from dataclasses import replace

    from visualenv.train.play import with_view
    from visualenv.env.registration import resolve

    loaded = visualenv.load_spec(resolve("Goalie-v0"))
    assert with_view(loaded) is loaded  # nothing asked: the same spec
    render = loaded.spec.render
    wide = loaded.spec.model_copy(
        update={"render": render.model_copy(update={"view": render.view.model_copy(update={"resolution": [400, 300]})})}
    )
    changed = with_view(replace(loaded, spec=wide), preset="fast", size=200)
    assert changed.spec.render.view.preset == "fast" and changed.spec.render.view.resolution == [200, 150]
    assert wide.render.view.preset == "quality"  # the original is untouched
