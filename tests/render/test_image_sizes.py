"""Images a spec names are sized from their headers before Blender or Pillow reads them: a PNG of a few kilobytes whose
header says 30,000 x 30,000 (Blender allocated 14 GB for it as a texture) is a located error of `visualenv build`."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from tests.fixtures.hostile_files import exr_header, npy_header, png_header
from visualenv.cli import main

pytestmark = pytest.mark.blender

SPEC = """\
id: Big-v0
scene:
  {limit}
  objects:
    Box: {{primitive: cube, material: {{texture: {{type: image, image: {texture}}}}}}}
    Ground: {{primitive: terrain, size: [20, 20, 1], segments: 8{heightmap}}}
    Cam: {{camera: perspective, location: [0, -5, 0], look_at: [0, 0, 0]}}
  world: {{image: {sky}}}
state: {{x: {{init: 0}}}}
actions: {{discrete: [{{}}]}}
observation: {{camera: Cam, resolution: [8, 8]}}
render: {{engine: cycles, preset: fast, view: {{resolution: [16, 16], preset: fast}}}}
"""


def build(tmp_path: Path, texture="small.png", sky="small.png", heightmap="", limit="") -> tuple[int, str]:
    pytest.importorskip("bpy")
    Image.fromarray(np.arange(64, dtype=np.uint8).reshape(8, 8)).save(tmp_path / "small.png")
    extra = f", heightmap: {heightmap}" if heightmap else ""
    text = SPEC.format(texture=texture, sky=sky, heightmap=extra, limit=limit)
    (tmp_path / "spec.yaml").write_text(text)
    start = time.monotonic()
    result = CliRunner().invoke(main, ["build", str(tmp_path / "spec.yaml"), "-o", str(tmp_path / "out"), "--quiet"])
    assert time.monotonic() - start < 60
    assert "Traceback" not in result.output and "DecompressionBomb" not in result.output, result.output
    return result.exit_code, result.output


def test_a_texture_whose_header_says_30000_squared_is_refused_before_blender_reads_it(tmp_path: Path) -> None:
    png_header(tmp_path / "bomb.png", 30_000, 30_000, mode=2)
    code, output = build(tmp_path, texture="bomb.png")
    assert code != 0 and "spec.yaml:5:" in output and "scene.objects.Box.material.texture.image" in output, output
    assert "30000 x 30000 pixels, more than the 67108864" in output and "scene.max_image_pixels" in output


def test_heightmaps_and_skies_are_sized_first_too(tmp_path: Path) -> None:
    png_header(tmp_path / "dem.png", 30_000, 30_000)
    code, output = build(tmp_path, heightmap="dem.png")
    assert code != 0 and "spec.yaml:6:" in output and "Ground.heightmap" in output, output
    assert "30000 x 30000 pixels" in output
    npy_header(tmp_path / "dem.npy", (100_000, 100_000))
    code, output = build(tmp_path, heightmap="dem.npy")
    assert code != 0 and "Ground.heightmap" in output and "100000 x 100000: more than" in output, output
    exr_header(tmp_path / "sky.exr", 40_000, 20_000)
    code, output = build(tmp_path, sky="sky.exr")
    assert code != 0 and "scene.world.image" in output and "40000 x 20000 pixels" in output, output


def test_the_spec_sets_the_limit(tmp_path: Path) -> None:
    code, output = build(tmp_path, limit="max_image_pixels: 32")
    assert code != 0 and "small.png is 8 x 8 pixels, more than the 32" in output, output
    code, output = build(tmp_path, limit="max_image_pixels: 64")
    assert code == 0, output
