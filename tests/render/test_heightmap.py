"""Terrain from elevation data (``primitive: terrain`` with ``heightmap:``): real geometry, seen in depth renders."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from visualenv.errors import SpecError
from visualenv.render.terrain import heightmap_heights, read_heightmap
from visualenv.spec import load_spec_text

pytestmark = pytest.mark.blender

EXAMPLE = Path(__file__).parents[2] / "examples" / "heightmaps"

#: a 20 m square ground seen straight down from 20 m by an orthographic camera; depth bytes are tenths of a metre
SPEC = """\
id: Dem-v0
scene:
  objects:
    Ground: {{primitive: terrain, heightmap: {file}, size: [20, 20, {top}], segments: 64{extra}}}
    Cam: {{camera: orthographic, ortho_scale: 20, location: [0, 0, 20]}}
state: {{x: {{init: 0.0}}}}
actions: {{discrete: [{{}}]}}
observation: {{camera: Cam, resolution: [32, 32], color: depth, depth_range: [0, 25.5]}}
"""


def bump(side: int = 65) -> np.ndarray:
    """A Gaussian hill in the middle of a flat square, 1 at its top; north (row 0) is +y."""
    rows, cols = np.mgrid[0:side, 0:side] / (side - 1) * 20  # metres from the north-west corner
    x, y = cols - 10, 10 - rows
    return np.exp(-(x**2 + (y - 2) ** 2) / (2 * 2.0**2))


def depth(tmp_path: Path, file: str, *, top: float = 4.0, extra: str = "", batch: int = 0) -> np.ndarray:
    from visualenv.env.batch import BatchedVectorEnv
    from visualenv.env.visual_env import VisualEnv

    loaded = load_spec_text(SPEC.format(file=file, top=top, extra=extra), name="dem.yaml", base_dir=tmp_path)
    env: BatchedVectorEnv | VisualEnv = BatchedVectorEnv(loaded, batch) if batch else VisualEnv(loaded)
    try:
        obs = env.reset(seed=0)[0]
        return (obs[-1] if batch else obs)[..., 0].astype(float) / 10  # metres from the camera
    finally:
        env.close()


def expected_depth(top: float = 4.0) -> np.ndarray:
    """The depth of each pixel centre of the 32 x 32 view: 20 m less the hill's height there (row 0 looks north)."""
    centres = (np.arange(32) + 0.5) / 32 * 20 - 10
    x, y = np.meshgrid(centres, -centres)
    return 20 - top * np.exp(-(x**2 + (y - 2) ** 2) / (2 * 2.0**2))


def test_a_bump_in_the_heightmap_is_a_hill_in_the_depth_render(tmp_path):
    np.save(tmp_path / "bump.npy", bump() * 37.5 + 1200)  # a DEM in metres: only its relative relief counts
    seen = depth(tmp_path, "bump.npy")
    want = expected_depth()
    assert np.abs(seen - want).max() <= 0.25, np.abs(seen - want).max()
    top = np.unravel_index(np.argmin(seen), seen.shape)
    assert abs(seen[top] - 16.0) <= 0.2 and top[0] < 16  # the hill's top is 4 m up, north of the centre (y = +2)
    assert seen[0, 0] == pytest.approx(20.0, abs=0.1) and seen[-1, -1] == pytest.approx(20.0, abs=0.1)


def test_8_and_16_bit_pngs_and_craters_on_top(tmp_path):
    Image.fromarray(np.round(bump() * 65535).astype(np.uint16)).save(tmp_path / "bump16.png")
    Image.fromarray(np.round(bump() * 255).astype(np.uint8)).save(tmp_path / "bump8.png")
    assert Image.open(tmp_path / "bump16.png").mode.startswith("I")
    want = expected_depth(top=2.0)
    for file in ("bump16.png", "bump8.png"):
        assert np.abs(depth(tmp_path, file, top=2.0) - want).max() <= 0.25, file
    cratered = depth(
        tmp_path, "bump16.png", top=2.0, extra=", craters: {count: 1, radius: [3, 3], depth: 0.2, rim: 0.0, seed: 0}"
    )
    assert (cratered - want).max() >= 1.0  # a 1.2 m deep bowl pressed into the hill's ground


def test_a_batch_renders_the_same_terrain(tmp_path):
    np.save(tmp_path / "bump.npy", bump())
    assert np.abs(depth(tmp_path, "bump.npy", batch=2) - expected_depth()).max() <= 0.25


def test_heights_are_sampled_bilinearly_and_scaled_to_z():
    heights = np.array([[0.0, 1.0], [0.0, 0.0]])  # north-east corner high
    z = heightmap_heights(np.array([5.0, -5.0, 0.0]), np.array([5.0, 5.0, 0.0]), heights, (10.0, 10.0, 3.0))
    assert z.tolist() == pytest.approx([3.0, 0.0, 0.75])


def test_the_bundled_example_is_made_by_its_script(tmp_path):
    out = tmp_path / "highlands.png"
    subprocess.run(
        [sys.executable, str(EXAMPLE / "make_highlands.py"), str(out)], check=True, capture_output=True, timeout=60
    )
    assert out.read_bytes() == (EXAMPLE / "highlands.png").read_bytes()
    heights = read_heightmap(EXAMPLE / "highlands.png")
    assert heights.shape == (257, 257) and heights.min() == 0 and heights.max() == 1
    assert (EXAMPLE / "highlands.png").stat().st_size < 1_000_000


@pytest.mark.parametrize(
    "make, size, message",
    [
        (
            lambda p: Image.new("RGB", (8, 8)).save(p / "map.png"),
            "[20, 20, 4]",
            "is a RGB image: a heightmap is one channel",
        ),
        (lambda p: None, "[20, 20, 4]", "heightmap file not found"),
        (lambda p: np.save(p / "map.npy", np.array([[1.0, np.nan], [0.0, 1.0]])), "[20, 20, 4]", "NaN or infinite"),
        (lambda p: (p / "map.png").write_text("not an image"), "[20, 20, 4]", "cannot read"),
    ],
)
def test_a_bad_heightmap_is_a_located_error_at_build(tmp_path, make, size, message):
    from visualenv.env.visual_env import VisualEnv

    make(tmp_path)
    file = "map.npy" if "NaN" in message else "map.png"
    text = SPEC.format(file=file, top=4, extra="").replace("[20, 20, 4]", size)
    env = VisualEnv(load_spec_text(text, name="dem.yaml", base_dir=tmp_path))
    try:
        with pytest.raises(SpecError, match=message) as err:
            env.reset(seed=0)
        assert "dem.yaml:4" in str(err.value) and "heightmap" in str(err.value)
    finally:
        env.close()


def test_a_heightmap_needs_a_height_and_only_a_terrain_takes_one():
    base = "id: D-v0\nstate: {x: {init: 0}}\nactions: {discrete: [{}]}\nscene:\n  objects:\n    G: "
    with pytest.raises(SpecError, match=r"needs size: \[x, y, z\]"):
        load_spec_text(base + "{primitive: terrain, heightmap: m.png, size: 20}\n", name="d.yaml")
    with pytest.raises(SpecError, match="'heightmap' does nothing on a cube"):
        load_spec_text(base + "{primitive: cube, heightmap: m.png}\n", name="d.yaml")
    toml = 'id = "D-v0"\n[state.x]\ninit = 0\n[actions]\ndiscrete = [{}]\n[scene.objects.G]\nprimitive = "terrain"\nheightmap = "m.png"\nsize = [20, 20, 4]\n'
    assert load_spec_text(toml, name="d.toml").spec.scene.objects["G"].heightmap == "m.png"


def test_tiffs_of_floats_and_16_bit_integers_read_as_the_same_relief(tmp_path):
    relief = np.random.default_rng(0).random((9, 7))
    Image.fromarray(relief.astype(np.float32)).save(tmp_path / "f.tif")
    Image.fromarray(np.round(relief * 65535).astype(np.uint16)).save(tmp_path / "i.tif")
    want = (relief - relief.min()) / (relief.max() - relief.min())
    for name in ("f.tif", "i.tif"):
        assert np.abs(read_heightmap(tmp_path / name) - want).max() < 1e-4, name
