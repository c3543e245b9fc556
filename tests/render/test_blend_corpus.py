"""Users' .blend files: the spec's render settings win whatever the file holds.

tests/fixtures/blend_corpus.py saves a small scene with one setting changed per file (video output,
AgX, a compositor, keyframes on the bound object, `Cube.001`, a missing library...). Each file gets a
spec that binds the ball's location; rendered with real bpy it must give the pixels the unchanged
base file gives (or, where the file changes what is drawn, still follow the binding), or fail with a
located ``scene.file`` error. Never a traceback, never a hang.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.fixtures.blend_corpus import VARIANTS, Variant  # noqa: E402
from visualenv.env import VisualEnv  # noqa: E402
from visualenv.errors import SpecError  # noqa: E402
from visualenv.spec import load_spec_text  # noqa: E402

pytestmark = pytest.mark.blender


def corpus_env(folder: Path, name: str, variant: Variant) -> VisualEnv:
    scene = f"file: {name}.blend, world: {{color: [0, 0, 0], strength: 0}}"
    if variant.file_scene:
        scene += f", file_scene: {json.dumps(variant.file_scene)}"
    extra = f", {variant.extra_actors}" if variant.extra_actors else ""
    text = f"""\
id: CorpusTest-v0
scene: {{{scene}}}
state: {{x: {{init: 0.0}}}}
actions: {{discrete: [{{u: 0}}]}}
actors:
  {json.dumps(variant.ball, ensure_ascii=False)}: {{location: [x, 0, 0]{extra}}}
observation: {{camera: {json.dumps(variant.camera, ensure_ascii=False)}, resolution: [48, 32], color: rgb}}
render: {{engine: cycles, preset: fast}}
"""
    return VisualEnv(load_spec_text(text, name=f"{name}.yaml", base_dir=folder))


def observe_both(env: VisualEnv) -> tuple[np.ndarray, np.ndarray]:
    try:
        left, _ = env.reset(seed=0, options={"state": {"x": -1.5}})
        right, _ = env.reset(seed=0, options={"state": {"x": 1.5}})
        return left, right
    finally:
        env.close()


def centroid_x(img: np.ndarray) -> float:
    bright = img.max(axis=2) > 60
    assert bright.any(), "nothing bright in the image"
    return float(np.nonzero(bright)[1].mean())


@pytest.fixture(scope="session")
def base_images(corpus) -> tuple[np.ndarray, np.ndarray]:
    return observe_both(corpus_env(corpus, "base", VARIANTS["base"]))


def test_the_corpus_script_makes_every_setting(corpus):
    made = json.loads((corpus / "made.json").read_text())
    assert {name: result for name, result in made.items() if result != "ok"} == {}
    assert (corpus / "compressed.blend").read_bytes()[:4] == b"\x28\xb5\x2f\xfd"  # zstd


@pytest.mark.parametrize("name", [n for n in VARIANTS if n != "base"])
def test_a_file_with_one_setting_changed_renders_as_the_spec_says(corpus, base_images, name):
    variant = VARIANTS[name]
    blend = corpus / f"{name}.blend"
    before = blend.read_bytes()
    if variant.error:
        with pytest.raises(SpecError, match=variant.error) as info:
            corpus_env(corpus, name, variant).renderer
        assert info.value.diagnostics[0].path == "scene.file" and info.value.diagnostics[0].line == 2
        return
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        left, right = observe_both(corpus_env(corpus, name, variant))
    if variant.warning:
        assert any(variant.warning in str(w.message) for w in caught), [str(w.message) for w in caught]
    assert left.shape == (32, 48, 3)
    assert centroid_x(right) - centroid_x(left) > 10  # the binding moves the ball
    if variant.same_pixels:
        assert np.array_equal(left, base_images[0]) and np.array_equal(right, base_images[1])
    else:
        assert not np.array_equal(left, base_images[0])  # the file's change shows (a modifier, a texture)
    assert blend.read_bytes() == before  # the user's file is never modified


def test_a_file_that_crashes_blender_is_a_located_error(corpus, monkeypatch):
    """No .blend that segfaults bpy 5.0.1 could be made with bpy itself: the reader here is a child
    that dies of a real SIGSEGV when asked to read, as Blender does on such a file."""
    from visualenv.render.blender.scene import blendfile

    crashing = blendfile._Reader(
        [sys.executable, "-c", "import os, signal, sys; sys.stdin.readline(); os.kill(os.getpid(), signal.SIGSEGV)"]
    )
    monkeypatch.setattr(blendfile, "_reader", crashing)
    monkeypatch.setattr(blendfile, "_answers", {})
    with pytest.raises(
        SpecError,
        match=r"Blender crashed \(signal SIGSEGV\) while reading .*base\.blend: open it in Blender and save it again",
    ) as info:
        corpus_env(corpus, "base", VARIANTS["base"]).renderer
    assert info.value.diagnostics[0].path == "scene.file" and info.value.diagnostics[0].line == 2
    assert crashing.proc is None  # the dead reader is forgotten; the next request starts a new one


def test_a_truncated_file_is_a_located_error(corpus, tmp_path):
    (tmp_path / "cut.blend").write_bytes((corpus / "base.blend").read_bytes()[:4000])
    with pytest.raises(SpecError, match=r"scene\.file: cannot read .*cut\.blend as a \.blend file: .*") as info:
        corpus_env(tmp_path, "cut", VARIANTS["base"]).renderer
    assert info.value.diagnostics[0].line == 2
