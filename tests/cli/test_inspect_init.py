"""`visualenv inspect` and `visualenv init` over files of the .blend corpus (tests/fixtures/blend_corpus.py)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from visualenv.cli import main

pytestmark = pytest.mark.blender

pytest.importorskip("bpy")


def test_inspect_lists_what_a_spec_needs(corpus):
    result = CliRunner().invoke(main, ["inspect", str(corpus / "keyframes.blend")])
    assert result.exit_code == 0, result.output
    text = result.output
    assert "scene Scene: camera Cam" in text and "Cam: ortho, lens 50 mm, ortho scale 6" in text
    assert "Lamp: sun, 3 W" in text and "Ball: 1.2 x 1.2 x 1.2 m" in text
    assert "material Paint: takes a `color` binding" in text
    assert "animated: location (keyframes)" in text
    assert "overridden by visualenv: engine: 'BLENDER_EEVEE'" in text and "view transform: 'AgX'" in text


def test_inspect_json_and_what_is_missing(corpus):
    result = CliRunner().invoke(main, ["inspect", "--json", str(corpus / "missing_library.blend")])
    assert result.exit_code == 0, result.output
    info = json.loads(result.output)
    assert [m["name"] for m in info["meshes"]] == ["Ball"] and info["cameras"][0]["name"] == "Cam"
    assert info["libraries"] == [{"path": "//library_gone.blend", "found": False, "uses": ["BallMesh"]}]
    text = CliRunner().invoke(main, ["inspect", str(corpus / "missing_texture.blend")]).output
    assert "image Checker: file //textures/does_not_exist.png NOT FOUND" in text
    compositor = CliRunner().invoke(main, ["inspect", str(corpus / "compositor.blend")]).output
    assert "compositor: 'Invert' (visualenv: off)" in compositor


def test_inspect_refuses_a_file_that_is_not_a_blend(tmp_path):
    (tmp_path / "notes.blend").write_text("hello")
    result = CliRunner().invoke(main, ["inspect", str(tmp_path / "notes.blend")])
    assert result.exit_code == 1 and result.output.strip().startswith("error: not a Blender file:")
    assert len(result.output.strip().splitlines()) == 1


@pytest.mark.parametrize("name", ["name_spaces", "two_scenes"])
def test_init_writes_a_spec_that_builds_unchanged_and_with_its_examples(corpus, tmp_path, name):
    spec = tmp_path / "specs" / "starter.yaml"
    runner = CliRunner()
    result = runner.invoke(main, ["init", str(corpus / f"{name}.blend"), "-o", str(spec)])
    assert result.exit_code == 0, result.output
    assert runner.invoke(main, ["validate", str(spec)]).output.strip() == "ok"
    built = runner.invoke(main, ["build", str(spec), "--out", str(tmp_path / "build"), "--quiet"])
    assert built.exit_code == 0, built.output
    # the commented example bindings are valid too: uncommented, the mesh follows the state
    text = spec.read_text()
    assert '#  "My Cube": {location: [x, 0, 0]}' in text if name == "name_spaces" else "file_scene: Main" in text
    lines = [line[2:] if line.startswith("#  ") and "location" in line else line for line in text.splitlines()]
    spec.write_text("\n".join(line.replace("actors: {}", "actors:") for line in lines) + "\n")
    from visualenv.env import VisualEnv
    from visualenv.spec.loader import load_spec

    env = VisualEnv(load_spec(spec))
    try:
        left, _ = env.reset(seed=0, options={"state": {"x": -1.0}})
        right, _ = env.reset(seed=0, options={"state": {"x": 1.0}})
        assert not (left == right).all()
    finally:
        env.close()
    assert runner.invoke(main, ["init", str(corpus / f"{name}.blend"), "-o", str(spec)]).output.startswith(
        f"error: {spec} exists"
    )
