"""Sizes read from files' headers before the files are (visualenv/files.py): each hostile file is small, says it is
huge, and is refused at once, without the allocation it asks for."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.fixtures.hostile_files import exr_header, hdr_header, npy_header, png_header
from visualenv.files import MAX_IMAGE_PIXELS, FileSizeError, check_image, image_size, json_depth, read_json
from visualenv.render.terrain import HeightmapError, read_heightmap


@pytest.mark.parametrize("suffix", ["png", "jpg", "tiff", "bmp", "webp", "tga"])
def test_the_size_of_an_image_is_read_from_its_header(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"image.{suffix}"
    Image.new("L" if suffix != "jpg" else "RGB", (37, 21)).save(path)
    assert image_size(path) == (37, 21)


def test_exr_and_hdr_headers_give_their_sizes(tmp_path: Path) -> None:
    assert image_size(exr_header(tmp_path / "sky.exr", 40000, 20000)) == (40000, 20000)
    assert image_size(hdr_header(tmp_path / "sky.hdr", 40000, 20000)) == (40000, 20000)


def test_an_image_over_the_limit_is_refused_from_its_header(tmp_path: Path) -> None:
    bomb = png_header(tmp_path / "bomb.png", 30_000, 30_000)
    assert bomb.stat().st_size < 100_000
    start = time.monotonic()
    with pytest.raises(FileSizeError, match="30000 x 30000 pixels, more than the 67108864 .*scene.max_image_pixels"):
        check_image(bomb, MAX_IMAGE_PIXELS, "scene.max_image_pixels")
    assert time.monotonic() - start < 5
    assert check_image(bomb, 30_000 * 30_000, "x") == (30_000, 30_000)  # a raised limit lets it through


def test_a_file_that_is_no_image_has_no_size(tmp_path: Path) -> None:
    (tmp_path / "x.png").write_text("not an image")
    assert image_size(tmp_path / "x.png") is None
    with pytest.raises(FileSizeError, match="cannot read .*not an image whose size"):
        check_image(tmp_path / "x.png", MAX_IMAGE_PIXELS, "x")


def test_a_png_heightmap_over_the_limit_is_refused_before_pillow_decodes_it(tmp_path: Path) -> None:
    bomb = png_header(tmp_path / "dem.png", 30_000, 30_000)
    with pytest.raises(HeightmapError, match="30000 x 30000 pixels, more than .*scene.max_image_pixels"):
        read_heightmap(bomb)
    small = tmp_path / "small.png"
    Image.fromarray(np.arange(64, dtype=np.uint8).reshape(8, 8)).save(small)
    with pytest.raises(HeightmapError, match="8 x 8 pixels, more than the 10"):
        read_heightmap(small, max_pixels=10)
    assert read_heightmap(small).shape == (8, 8)


def test_a_npy_heightmap_whose_header_claims_too_much_is_refused_before_loading(tmp_path: Path) -> None:
    liar = npy_header(tmp_path / "dem.npy", (100_000, 100_000))
    with pytest.raises(HeightmapError, match="100000 x 100000: more than 67108864 values .*scene.max_image_pixels"):
        read_heightmap(liar)
    short = npy_header(tmp_path / "short.npy", (100, 100))  # within the limit, and holding none of its data
    with pytest.raises(HeightmapError, match="the file holds 0"):
        read_heightmap(short)
    with pytest.raises(HeightmapError, match="2-D numbers"):
        np.save(tmp_path / "cube.npy", np.zeros((2, 2, 2)))
        read_heightmap(tmp_path / "cube.npy")
    np.save(tmp_path / "ok.npy", np.eye(3))
    assert read_heightmap(tmp_path / "ok.npy").shape == (3, 3)


def test_json_nested_200000_deep_is_refused_before_parsing(tmp_path: Path) -> None:
    path = tmp_path / "policy.json"
    path.write_text("[" * 200_000 + "]" * 200_000)
    start = time.monotonic()
    with pytest.raises(FileSizeError, match="nested 200000 deep, more than the 64 levels"):
        read_json(path)
    assert time.monotonic() - start < 5


def test_brackets_inside_strings_do_not_nest(tmp_path: Path) -> None:
    value = {"a": '[[[{{\\"[[', "b": [[1, {"c": "]]]"}]]}
    (tmp_path / "x.json").write_text(json.dumps(value))
    assert json_depth(json.dumps(value)) == 4
    assert read_json(tmp_path / "x.json") == value
    with pytest.raises(FileSizeError, match="larger than the 10 bytes"):
        read_json(tmp_path / "x.json", max_bytes=10)
