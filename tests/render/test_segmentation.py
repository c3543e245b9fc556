"""Segmentation observations (``color: segmentation``): exact object ids per pixel, labels, .blend objects, batches."""

from __future__ import annotations

import numpy as np
import pytest

from visualenv.errors import SpecError
from visualenv.spec import load_spec_text

pytestmark = pytest.mark.blender

#: seen straight down by an orthographic camera: 8 m over 32 pixels, shifted so that object edges cross pixels a quarter and
#: three eighths of the way: a pixel that blended samples from its whole area would see two ids there
SCENE = """\
id: Seg-v0
scene:
  {file}world: {{color: [0.5, 0.6, 0.7]}}
  objects:
    Floor: {{primitive: plane, size: 6, material: {{color: [0.3, 0.3, 0.3]}}}}
    A: {{primitive: cube, size: 1, location: [-2, -1.5, 0.5], label: box}}
    B: {{primitive: cube, size: 1, location: [1.5, -1.5, 0.5], label: box, material: {{color: [0.9, 0.1, 0.1]}}}}
    Glass: {{primitive: cube, size: [1, 2, 1], location: [0.5, 1.5, 0.5], material: {{color: [0.2, 0.9, 0.2, 0.4]}}}}
    Lamp: {{light: point, strength: 300, location: [-1.5, 1.5, 3], size: 0.6}}
    Sun: {{light: sun, strength: 2}}
    Cam: {{camera: orthographic, ortho_scale: 8, location: [0.0625, 0.09375, 10]}}
state: {{x: {{init: "{init}"}}}}
actions: {{discrete: [{{u: 0.25}}, {{u: -0.25}}]}}
dynamics: {{update: {{x: x + u}}}}
actors: {{A: {{location: [x, -1.5, 0.5]}}}}
observation:
  cameras:
    rgb: {{camera: Cam, resolution: [32, 32], color: rgb}}
    seg: {{camera: Cam, resolution: [32, 32], color: segmentation}}
"""


def expected(x: float, ids: dict[str, int], crate: bool = False) -> np.ndarray:
    """The id each pixel centre sees from above: the boxes (A at x), the glass box, the floor, else 0."""
    centres = (np.arange(32) + 0.5) * 0.25 - 4
    px, py = np.meshgrid(centres + 0.0625, 0.09375 - centres)  # row 0 looks north (+y)

    def inside(cx: float, cy: float, sx: float, sy: float) -> np.ndarray:
        return (np.abs(px - cx) < sx / 2) & (np.abs(py - cy) < sy / 2)

    out = np.zeros((32, 32), dtype=np.uint8)
    out[inside(0, 0, 6, 6)] = ids["Floor"]
    out[inside(x, -1.5, 1, 1) | inside(1.5, -1.5, 1, 1)] = ids["box"]
    out[inside(0.5, 1.5, 1, 2)] = ids["Glass"]
    if crate:
        out[inside(-2.5, 2.5, 1, 1)] = ids["Crate"]
    return out


def run(text: str, actions: list[int], name: str = "seg.yaml", base_dir=".") -> tuple[list, list, dict]:
    from visualenv.env.visual_env import VisualEnv

    env = VisualEnv(load_spec_text(text, name=name, base_dir=base_dir))
    try:
        obs, info = env.reset(seed=0)
        seen, states = [obs], [info["state"].get("x")]
        for a in actions:
            obs, _, _, _, info = env.step(a)
            seen.append(obs)
            states.append(info["state"].get("x"))
        return seen, states, env.segmentation_ids
    finally:
        env.close()


def test_each_pixel_holds_the_id_of_what_it_sees_exactly():
    """Shared labels share an id; a see-through surface and a lamp in view change nothing; ids follow a moving object."""
    seen, states, ids = run(SCENE.format(file="", init=-2.0), [0, 0, 1])
    assert ids == {"Floor": 1, "box": 2, "Glass": 3}
    for obs, x in zip(seen, states):
        seg = obs["seg"]
        assert seg.shape == (32, 32, 1) and seg.dtype == np.uint8
        want = expected(x, ids)
        assert np.array_equal(seg[:, :, 0], want), np.argwhere(seg[:, :, 0] != want)
    rgb = seen[0]["rgb"].astype(int)
    assert (
        rgb[22, 22, 0] > rgb[22, 22, 1] + 50 and len(np.unique(rgb.reshape(-1, 3), axis=0)) > 4
    )  # the colour camera still sees red box B


def test_a_colour_camera_beside_a_segmentation_camera_renders_as_it_does_alone():
    text = SCENE.format(file="", init=-2.0)
    alone = text.replace("    seg: {camera: Cam, resolution: [32, 32], color: segmentation}\n", "")
    with_seg, _, _ = run(text, [0, 1])
    without, _, ids = run(alone, [0, 1])
    assert ids == {}
    for a, b in zip(with_seg, without):
        assert np.array_equal(a["rgb"], b["rgb"])


def test_a_batch_gives_each_env_its_own_exact_ids():
    from visualenv.env.batch import BatchedVectorEnv

    text = SCENE.format(file="", init="uniform(-2.5, -1.5)")
    batch = BatchedVectorEnv(load_spec_text(text, name="seg.yaml"), 3)
    try:
        obs, info = batch.reset(seed=4)
        ids = batch.segmentation_ids
        for _ in range(2):
            obs, _, _, _, info = batch.step(np.array([0, 1, 0]))
        for i in range(3):
            assert np.array_equal(obs["seg"][i, :, :, 0], expected(info["state"]["x"][i], ids)), i
    finally:
        batch.close()


def test_objects_of_a_blend_file_take_part_by_name(tmp_path):
    import bpy

    scene = bpy.data.scenes.new("crate-scene")
    mesh = bpy.data.meshes.new("crate-mesh")
    mesh.from_pydata(
        [(x, y, z) for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (0, 1)],
        [],
        [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)],
    )
    crate = bpy.data.objects.new("Crate", mesh)
    crate.location = (-2.5, 2.5, 0)
    scene.collection.objects.link(crate)
    bpy.data.libraries.write(str(tmp_path / "crate.blend"), {scene})
    bpy.data.objects.remove(crate)
    bpy.data.meshes.remove(mesh)
    bpy.data.scenes.remove(scene)
    seen, states, ids = run(SCENE.format(file="file: crate.blend\n  ", init=-2.0), [], base_dir=tmp_path)
    assert ids == {"Crate": 1, "Floor": 2, "box": 3, "Glass": 4}
    assert np.array_equal(seen[0]["seg"][:, :, 0], expected(states[0], ids, crate=True))


def test_a_single_segmentation_camera_in_toml():
    text = """\
id = "SegToml-v0"
[scene.objects.Ball]
primitive = "cube"
size = 2
label = "target"
[scene.objects.Cam]
camera = "orthographic"
ortho_scale = 8
location = [0, 0, 10]
[state.x]
init = 0.0
[actions]
discrete = [{}]
[observation]
camera = "Cam"
resolution = [16, 16]
color = "segmentation"
"""
    seen, _, ids = run(text, [], name="seg.toml")
    assert ids == {"target": 1}
    want = np.zeros((16, 16), dtype=np.uint8)
    want[6:10, 6:10] = 1
    assert np.array_equal(seen[0][:, :, 0], want)


@pytest.mark.parametrize(
    "fragment, message",
    [
        ("observation: {camera: Cam, color: segmentation, sensor: {read_noise: 0.1}}", "a sensor model acts on light"),
        ("scene: {objects: {L: {light: sun, label: lamp}}}\nobservation: {camera: Cam, color: segmentation}", "label"),
        (
            "scene: {objects: {C: {primitive: cube, label: 'two words'}}}\nobservation: {camera: Cam, color: segmentation}",
            "expected a name made of letters",
        ),
    ],
)
def test_bad_segmentation_specs_are_located_errors(fragment, message):
    text = "id: Bad-v0\nstate: {x: {init: 0}}\nactions: {discrete: [{}]}\n" + fragment + "\n"
    with pytest.raises(SpecError, match=message) as err:
        load_spec_text(text, name="bad.yaml")
    assert "bad.yaml:" in str(err.value)


def test_mujoco_geoms_take_their_bodys_name():
    """Gymnasium's InvertedPendulum: the cart's and the pole's geoms each show as their body, the pole above the cart."""
    pytest.importorskip("mujoco")
    from pathlib import Path

    folder = Path(__file__).parents[2] / "specs" / "mujoco"
    text = (
        (folder / "inverted_pendulum.yaml")
        .read_text()
        .replace(
            "observation: {camera: Camera, resolution: [64, 64], color: grayscale}",
            "observation: {cameras: {eye: {camera: Camera, resolution: [48, 48], color: rgb}, mask: {camera: Camera, resolution: [48, 48], color: segmentation}}}",
        )
    )
    assert "mask:" in text
    seen, _, ids = run(text, [], base_dir=folder)
    assert set(ids) == {
        "world",
        "cart",
        "pole",
        "Post0",
        "PostL1",
        "PostR1",
        "PostL2",
        "PostR2",
    }  # bodies, then the spec's posts
    mask = seen[0]["mask"][:, :, 0]
    cart, pole = np.argwhere(mask == ids["cart"]), np.argwhere(mask == ids["pole"])
    assert len(cart) >= 8 and len(pole) >= 8
    assert pole[:, 0].min() < cart[:, 0].min() and set(np.unique(mask)) <= {0, *ids.values()}
