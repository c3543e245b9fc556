"""Image skies (``world: {image: ...}``): an environment map that shows behind the scene and lights it, bound through ``World``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from visualenv.errors import SpecError
from visualenv.spec import load_spec_text

pytestmark = pytest.mark.blender


def write_hdr(path: Path, rgb: np.ndarray) -> None:
    """A Radiance .hdr (flat RGBE scanlines) of a float (H, W, 3) image: how a test makes an HDR sky without another library."""
    height, width, _ = rgb.shape
    top = rgb.max(axis=2)
    exponent = np.where(top > 1e-32, np.ceil(np.log2(np.maximum(top, 1e-32)) + 1e-9), -128)
    mantissa = np.where(top[..., None] > 1e-32, rgb / np.exp2(exponent)[..., None] * 256, 0)
    rgbe = np.concatenate([np.clip(mantissa, 0, 255), (exponent + 128)[..., None]], axis=2).astype(np.uint8)
    header = f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {height} +X {width}\n".encode()
    path.write_bytes(header + rgbe.tobytes())


def halves(path: Path, left: tuple, right: tuple) -> None:
    """An equirectangular PNG sky: one colour on the left half of the panorama, another on the right."""
    image = np.zeros((32, 64, 3), dtype=np.uint8)
    image[:, :32] = left
    image[:, 32:] = right
    Image.fromarray(image).save(path)


#: a camera on the horizon looking along +y at nothing but sky; a white floor below a second camera looking down
SPEC = """\
id: Sky-v0
scene:
  world: {{image: {image}, strength: {strength}, rotation: {rotation}}}
  objects:
    Floor: {{primitive: plane, size: 4, location: [0, 0, -50], material: {{color: [1, 1, 1], roughness: 1}}}}
    Horizon: {{camera: perspective, lens: 50, location: [0, 0, 0], rotation: [1.5708, 0, 0]}}
    Down: {{camera: perspective, lens: 50, location: [0, 0, -48]}}
state:
  yaw: {{init: 0.0}}
  power: {{init: {strength}}}
actions: {{discrete: [{{}}]}}
dynamics: {{update: {{yaw: yaw + pi, power: power * 2}}}}
{actors}
observation:
  cameras:
    sky: {{camera: Horizon, resolution: [16, 16], color: rgb}}
    floor: {{camera: Down, resolution: [16, 16], color: grayscale}}
"""


def frames(
    tmp_path: Path, *, image: str, strength: float = 1.0, rotation: str = "0.0", actors: str = "", steps: int = 0
) -> list[dict]:
    from visualenv.env.visual_env import VisualEnv

    text = SPEC.format(image=image, strength=strength, rotation=rotation, actors=actors)
    env = VisualEnv(load_spec_text(text, name="sky.yaml", base_dir=tmp_path))
    try:
        out = [env.reset(seed=0)[0]]
        out += [env.step(0)[0] for _ in range(steps)]
        return out
    finally:
        env.close()


def mean_rgb(obs: dict) -> np.ndarray:
    return obs["sky"].reshape(-1, 3).mean(axis=0)


def test_the_image_shows_behind_the_scene_and_turns_with_rotation(tmp_path):
    halves(tmp_path / "sky.png", (230, 20, 20), (20, 20, 230))
    ahead = mean_rgb(frames(tmp_path, image="sky.png")[0])
    behind = mean_rgb(frames(tmp_path, image="sky.png", rotation="3.14159")[0])
    seen = sorted([ahead, behind], key=lambda c: c[0])  # one view is the blue half, the other the red one
    assert seen[0][2] > 180 and seen[0][0] < 60, seen
    assert seen[1][0] > 180 and seen[1][2] < 60, seen


def test_an_hdr_sky_lights_the_scene_in_proportion_to_its_strength(tmp_path):
    write_hdr(tmp_path / "grey.hdr", np.full((16, 32, 3), 0.1, dtype=np.float32))
    dim = frames(tmp_path, image="grey.hdr", strength=0.5)[0]
    bright = frames(tmp_path, image="grey.hdr", strength=2.0)[0]
    dim_floor, bright_floor = dim["floor"].mean(), bright["floor"].mean()
    assert 10 < dim_floor < bright_floor - 40, (dim_floor, bright_floor)
    # the sky seen directly: radiance 0.05 and 0.2, as Blender's sRGB writes them
    assert abs(dim["sky"].mean() - 63) <= 3 and abs(bright["sky"].mean() - 124) <= 3, (
        dim["sky"].mean(),
        bright["sky"].mean(),
    )


def test_strength_and_rotation_bind_through_the_world_actor(tmp_path):
    halves(tmp_path / "sky.png", (230, 20, 20), (20, 20, 230))
    seen = frames(
        tmp_path, image="sky.png", strength=0.25, actors="actors: {World: {rotation: yaw, strength: power}}", steps=2
    )
    red = [mean_rgb(obs)[0] > mean_rgb(obs)[2] for obs in seen]
    assert red[0] != red[1] and red[0] == red[2]  # turned half a turn each step
    brightness = [obs["floor"].mean() for obs in seen]
    assert brightness[0] < brightness[1] < brightness[2]  # strength 0.25, 0.5, 1


def test_a_batch_shares_an_unbound_sky_and_refuses_a_bound_one(tmp_path):
    from visualenv.env.batch import BatchedVectorEnv

    halves(tmp_path / "sky.png", (230, 20, 20), (20, 20, 230))
    text = SPEC.format(image="sky.png", strength=1.0, rotation="0.0", actors="")
    batch = BatchedVectorEnv(load_spec_text(text, name="sky.yaml", base_dir=tmp_path), 2)
    try:
        obs, _ = batch.reset(seed=0)
    finally:
        batch.close()
    single = frames(tmp_path, image="sky.png")[0]
    for i in range(2):
        assert np.abs(obs["sky"][i].astype(int) - single["sky"].astype(int)).max() <= 2
    bound = SPEC.format(image="sky.png", strength=1.0, rotation="0.0", actors="actors: {World: {rotation: yaw}}")
    with pytest.raises(SpecError, match="a batch's envs share one world") as err:  # refused when the batch is built
        BatchedVectorEnv(load_spec_text(bound, name="sky.yaml", base_dir=tmp_path), 2)
    assert "sky.yaml:13" in str(err.value)


def test_bad_skies_are_located_errors(tmp_path):
    from visualenv.env.visual_env import VisualEnv

    def build(text: str) -> None:
        env = VisualEnv(load_spec_text(text, name="sky.yaml", base_dir=tmp_path))
        try:
            env.reset(seed=0)
        finally:
            env.close()

    with pytest.raises(SpecError, match="sky image not found") as err:
        build(SPEC.format(image="gone.hdr", strength=1.0, rotation="0.0", actors=""))
    assert "sky.yaml:3" in str(err.value)
    with pytest.raises(
        SpecError, match="the World actor binds the world's 'strength', 'rotation', 'color', not 'location'"
    ):
        load_and_compile(
            SPEC.format(image="x.png", strength=1.0, rotation="0.0", actors="actors: {World: {location: [0, 0, yaw]}}")
        )
    plain = SPEC.format(image="x.png", strength=1.0, rotation="0.0", actors="actors: {World: {rotation: yaw}}").replace(
        "image: x.png, ", ""
    )
    with pytest.raises(SpecError, match="'rotation' turns an image sky: give the world an 'image'"):
        build(plain.replace(", rotation: 0.0", ""))


def test_a_sky_in_toml():
    text = 'id = "Sky-v0"\n[scene.world]\nimage = "sky.exr"\nstrength = 0.5\nrotation = [0, 0, 1.2]\n[state.x]\ninit = 0\n[actions]\ndiscrete = [{}]\n'
    world = load_spec_text(text, name="sky.toml").spec.scene.world
    assert (world.image, world.strength, world.rotation, world.tint()) == ("sky.exr", 0.5, [0, 0, 1.2], [1.0, 1.0, 1.0])


def load_and_compile(text: str) -> None:
    from visualenv.compiler.program import compile_spec

    compile_spec(load_spec_text(text, name="sky.yaml"))
