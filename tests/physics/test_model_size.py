"""An MJCF model's memory, estimated before MuJoCo compiles it (visualenv/physics/model_size.py): a few hundred bytes
that ask for gigabytes are refused at once, through `visualenv validate`, naming the file and the element."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from click.testing import CliRunner

pytest.importorskip("mujoco")

from tests.fixtures.hostile_files import png_header  # noqa: E402
from visualenv.cli import main  # noqa: E402
from visualenv.files import FileSizeError  # noqa: E402
from visualenv.physics.model_size import check_model_size  # noqa: E402

#: a slider with a motor, and whatever the case adds: `{asset}` in <asset>, `{size}` before it
MODEL = """\
<mujoco>
  {size}
  <asset>
    {asset}
  </asset>
  <worldbody>
    <body><joint name="j" type="slide"/><geom type="sphere" size="0.1"/></body>
  </worldbody>
  <actuator><motor joint="j"/></actuator>
</mujoco>
"""


def validate(tmp_path: Path, asset: str = "", size: str = "", physics: str = "") -> tuple[int, str, float]:
    (tmp_path / "model.xml").write_text(MODEL.format(asset=asset, size=size))
    (tmp_path / "spec.yaml").write_text(f"id: Big-v0\nphysics: {{model: model.xml{physics}}}\n")
    start = time.monotonic()
    result = CliRunner().invoke(main, ["validate", str(tmp_path / "spec.yaml")])
    return result.exit_code, result.output, time.monotonic() - start


def test_a_20000_squared_height_field_is_refused_before_compiling(tmp_path: Path) -> None:
    code, output, seconds = validate(tmp_path, '<hfield name="ground" nrow="20000" ncol="20000" size="1 1 1 0.1"/>')
    assert (tmp_path / "model.xml").stat().st_size < 600
    assert code != 0 and seconds < 20, output
    assert "spec.yaml:2:" in output and "physics.model" in output and "Traceback" not in output
    assert "model.xml:4: <hfield name='ground'>: 7.5 GiB" in output and "physics.max_memory_mib" in output


def test_size_memory_8g_is_refused_before_compiling(tmp_path: Path) -> None:
    code, output, seconds = validate(tmp_path, size='<size memory="8G"/>')
    assert code != 0 and seconds < 20, output
    assert "model.xml:2: <size>: 8.0 GiB" in output and "Traceback" not in output and "FatalError" not in output


def test_a_raised_limit_lets_a_model_through(tmp_path: Path) -> None:
    code, output, _ = validate(tmp_path, size='<size memory="1500M"/>', physics=", max_memory_mib: 2048")
    assert code == 0 and output.strip() == "ok", output


def test_a_height_field_image_over_the_pixel_limit_is_refused_from_its_header(tmp_path: Path) -> None:
    png_header(tmp_path / "ground.png", 30_000, 30_000)
    code, output, seconds = validate(tmp_path, '<hfield name="g" file="ground.png" size="1 1 1 0.1"/>')
    assert code != 0 and seconds < 20, output
    assert "<hfield name='g'>" in output and "30000 x 30000 pixels" in output and "scene.max_image_pixels" in output


def test_textures_are_counted_builtin_and_from_files(tmp_path: Path) -> None:
    code, output, _ = validate(tmp_path, '<texture name="sky" type="skybox" builtin="checker" width="20000"/>')
    assert code != 0 and "<texture name='sky'>: 2400000000 pixels" in output, output
    png_header(tmp_path / "wall.png", 30_000, 30_000, mode=2)
    code, output, _ = validate(tmp_path, '<texture name="wall" type="2d" file="wall.png"/>')
    assert code != 0 and "<texture name='wall'>" in output and "30000 x 30000 pixels" in output, output


def test_included_files_are_read_and_named(tmp_path: Path) -> None:
    (tmp_path / "terrain.xml").write_text(
        '<mujocoinclude>\n  <asset>\n    <hfield name="far" nrow="9000" ncol="9000" size="1 1 1 0.1"/>\n'
        "  </asset>\n</mujocoinclude>\n"
    )
    (tmp_path / "model.xml").write_text(MODEL.format(asset="", size='<include file="terrain.xml"/>'))
    with pytest.raises(FileSizeError, match="terrain.xml:3: <hfield name='far'>"):
        check_model_size(tmp_path / "model.xml")


def test_the_machines_available_memory_is_a_limit_too(tmp_path: Path) -> None:
    (tmp_path / "model.xml").write_text(MODEL.format(asset="", size='<size memory="100M"/>'))
    assert 100 * 2**20 < check_model_size(tmp_path / "model.xml") < 101 * 2**20  # and 6 KB an element
    with pytest.raises(FileSizeError, match="more than this machine's available memory \\(50 MiB\\)"):
        check_model_size(tmp_path / "model.xml", available=50 * 2**20)


def test_replicated_elements_are_counted_with_their_copies(tmp_path: Path) -> None:
    (tmp_path / "model.xml").write_text(
        '<mujoco>\n<worldbody>\n<replicate count="1000" offset="1 0 0">\n<replicate count="1000" offset="0 1 0">\n'
        '<geom type="sphere" size="0.1"/>\n</replicate>\n</replicate>\n</worldbody>\n</mujoco>\n'
    )
    with pytest.raises(FileSizeError, match="model.xml:5: <geom> \\(1000000 copies\\): 5.7 GiB"):
        check_model_size(tmp_path / "model.xml")
    (tmp_path / "model.xml").write_text('<mujoco><worldbody><flexcomp count="500 500 500"/></worldbody></mujoco>')
    with pytest.raises(FileSizeError, match="<flexcomp>: 715.3 GiB"):
        check_model_size(tmp_path / "model.xml")
