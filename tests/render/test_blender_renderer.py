"""Real bpy renders through the whole path: spec -> compiled program -> env -> BlenderRenderer.

Small resolutions keep each render at a few milliseconds; every test looks at pixels.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visualenv.env import VisualEnv  # noqa: E402
from visualenv.errors import SpecError  # noqa: E402
from visualenv.spec import load_spec_text  # noqa: E402
from visualenv.render.frames import Frames  # noqa: E402

pytestmark = pytest.mark.blender

OBJECTS = """\
    Box:  {primitive: cube, size: 1.0, material: {color: [0.9, 0.9, 0.9]}}
    Sun:  {light: sun, strength: 4.0, rotation: [0.8, 0.0, 0.0]}
    Cam:  {camera: orthographic, ortho_scale: 6, location: [0, -10, 0], look_at: [0, 0, 0]}
"""


def make_env(
    tmp_path: Path,
    *,
    objects: str = OBJECTS,
    actors: str = "Box: {location: [x, 0, 0]}",
    observation: str = "{camera: Cam, resolution: [48, 32], color: rgb}",
    scene_extra: str = "",
    state: str = "x: {init: 0.0}",
    render: str = "{engine: cycles, preset: fast}",
    **renderer_options: Any,
) -> VisualEnv:
    text = f"""\
id: RenderTest-v0
scene:
{scene_extra}  world: {{color: [0.0, 0.0, 0.0], strength: 0.0}}
  objects:
{objects}
state:
{textwrap.indent(state, "  ")}
actions: {{discrete: [{{u: 0}}]}}
actors:
{textwrap.indent(actors, "  ")}
observation: {observation}
render: {render}
"""
    return VisualEnv(load_spec_text(text, name="t.yaml", base_dir=tmp_path), renderer_options=renderer_options)


def observe(env: VisualEnv, **state: float):
    obs, _ = env.reset(seed=0, options={"state": state})
    return obs


def centroid_x(img: np.ndarray, threshold: int = 60) -> float:
    bright = img.max(axis=2) > threshold
    assert bright.any(), "nothing bright in the image"
    return float(np.nonzero(bright)[1].mean())


@pytest.fixture
def env(tmp_path):
    e = make_env(tmp_path)
    yield e
    e.close()


def test_moving_an_actor_moves_its_pixels(env):
    left = observe(env, x=-1.5)
    right = observe(env, x=1.5)
    assert left.shape == (32, 48, 3) and left.dtype == np.uint8
    assert centroid_x(right) - centroid_x(left) > 10  # 3 m of a 6 m wide view on 48 px: 24 px
    assert left[0].max() < 20 and left[-1].max() < 20  # dark background above and below the box


def test_top_row_is_top_of_image(tmp_path):
    e = make_env(tmp_path, actors="Box: {location: [0, 0, z]}", state="z: {init: 0.0}")
    try:
        up = observe(e, z=2.0)
        rows = np.nonzero(up.max(axis=(1, 2)) > 60)[0]
        assert rows.mean() < 16  # a box above the centre appears in the upper half
    finally:
        e.close()


def test_bound_colour_changes_the_rendered_colour(tmp_path):
    e = make_env(tmp_path, actors="Box: {color: [1 - x, 0.05, x]}")
    try:
        red = observe(e, x=0.0).astype(int)
        blue = observe(e, x=1.0).astype(int)
        cy, cx = 16, 24
        assert red[cy, cx, 0] > red[cy, cx, 2] + 50
        assert blue[cy, cx, 2] > blue[cy, cx, 0] + 50
    finally:
        e.close()


@pytest.mark.parametrize(
    "binding", ["Box: {color: [0.9, 0.9, 0.9, x]}", "Box: {location: [0, 0, 0]}"], ids=["bound", "static"]
)
def test_colour_alpha_makes_an_object_see_through(tmp_path, binding):
    # a white box (alpha x) in front of a red wall: opaque it hides the wall, with alpha 0 the wall shows through
    objects = OBJECTS.replace(
        "[0.9, 0.9, 0.9]}", "[0.9, 0.9, 0.9, 0.0]}" if "location" in binding else "[0.9, 0.9, 0.9]}"
    )
    objects += (
        "    Wall: {primitive: cube, size: [6, 0.1, 6], location: [0, 2, 0], material: {color: [0.8, 0.02, 0.02]}}\n"
    )
    e = make_env(tmp_path, objects=objects, actors=binding)
    try:
        centre = observe(e, x=0.0).astype(int)[16, 24]
        assert centre[0] > centre[1] + 50, f"the red wall should show through: {centre}"
        assert e.renderer._scene.cycles.transparent_max_bounces > 0
        if "color" in binding:
            centre = observe(e, x=1.0).astype(int)[16, 24]
            assert abs(centre[0] - centre[1]) < 20 and centre[1] > 100, f"an opaque white box: {centre}"
    finally:
        e.close()


def test_opaque_scenes_skip_transparent_passes(env):
    # with any see-through pass allowed, Cycles traces shadows through every surface: +0.25 ms per CartPole render
    observe(env, x=0.0)
    assert env.renderer._scene.cycles.transparent_max_bounces == 0


def test_bound_colour_on_an_empty_colours_the_meshes_under_it(tmp_path):
    objects = OBJECTS.replace(
        "    Box:  {primitive: cube, size: 1.0,",
        "    Rig:  {empty: true}\n    Box:  {primitive: cube, size: 1.0, parent: Rig,",
    )
    e = make_env(tmp_path, objects=objects, actors="Rig: {color: [1 - x, 0.05, x]}")
    try:
        red, blue = observe(e, x=0.0).astype(int)[16, 24], observe(e, x=1.0).astype(int)[16, 24]
        assert red[0] > red[2] + 50 and blue[2] > blue[0] + 50
    finally:
        e.close()
    lonely = make_env(tmp_path, objects=OBJECTS + "    Rig:  {empty: true}\n", actors="Rig: {color: [1, 0, 0]}")
    with pytest.raises(
        SpecError,
        match="actors.Rig.color: a bound colour sets the materials of 'Rig' and the meshes under it, but it has none",
    ):
        lonely.renderer
    lonely.close()


def test_colour_binding_does_not_leak_to_other_objects(tmp_path):
    objects = (
        OBJECTS + "    Other: {primitive: cube, size: 1.0, location: [2, 0, 0], material: {color: [0.9, 0.9, 0.9]}}\n"
    )
    e = make_env(tmp_path, objects=objects, actors="Box: {color: [0.0, 0.0, x]}")
    try:
        img = observe(e, x=1.0).astype(int)
        box, other = img[16, 24], img[16, 24 + 16]  # 2 m right = 16 px
        assert box[2] > box[0] + 50
        assert abs(other[0] - other[2]) < 10  # still grey
    finally:
        e.close()


def test_grayscale_rgb_depth_shapes_and_depth_order(tmp_path):
    objects = """\
    Near: {primitive: cube, size: 1.0, location: [-1.5, -6, 0], material: {color: [0.9, 0.9, 0.9]}}
    Far:  {primitive: cube, size: 1.0, location: [1.5, 4, 0], material: {color: [0.9, 0.9, 0.9]}}
    Sun:  {light: sun, strength: 4.0, rotation: [0.8, 0.0, 0.0]}
    Cam:  {camera: orthographic, ortho_scale: 6, location: [0, -10, 0], look_at: [0, 0, 0]}
"""
    observation = """
  cameras:
    color: {camera: Cam, resolution: [40, 30], color: rgb}
    gray:  {camera: Cam, resolution: [40, 30], color: grayscale}
    depth: {camera: Cam, resolution: [40, 30], color: depth, depth_range: [0, 20]}"""
    e = make_env(tmp_path, objects=objects, actors="Near: {visible: x < 1}", observation=observation)
    try:
        obs = observe(e, x=0.0)
        assert set(obs) == {"color", "gray", "depth"}
        assert (
            obs["color"].shape == (30, 40, 3) and obs["gray"].shape == (30, 40, 1) and obs["depth"].shape == (30, 40, 1)
        )
        assert all(a.dtype == np.uint8 for a in obs.values())
        assert e.observation_space.contains(obs)
        depth = obs["depth"][:, :, 0].astype(int)
        near, far = depth[15, 10], depth[15, 30]  # x = -1.5 and +1.5 m on a 6 m view
        # front faces: near 3.5 m from the camera -> 3.5 / 20 * 255 = 45; far 13.5 m -> 172; background 255
        assert abs(near - 45) <= 2 and abs(far - 172) <= 2
        assert depth[0, 0] == 255
        gray = obs["gray"][:, :, 0].astype(int)
        rgb = obs["color"].astype(int)
        luma = (299 * rgb[..., 0] + 587 * rgb[..., 1] + 114 * rgb[..., 2] + 500) // 1000
        assert np.array_equal(gray, luma)
        assert gray[15, 10] > 60 and gray[0, 0] < 10
        hidden = observe(e, x=2.0)  # the near cube hidden: background behind it
        assert hidden["depth"][15, 10, 0] == 255
        again = observe(e, x=0.0)  # switching the depth override on and off leaves every view reproducible
        assert all(np.array_equal(again[k], obs[k]) for k in obs)
    finally:
        e.close()


THREE_VIEWS = """
  cameras:
    color: {camera: Cam, resolution: [40, 30], color: rgb}
    gray:  {camera: Cam, resolution: [40, 30], color: grayscale}
    depth: {camera: Cam, resolution: [40, 30], color: depth, depth_range: [0, 20]}"""


def test_memory_readback_matches_the_file_written_by_blender(tmp_path):
    """Pixels copied from Cycles' result equal Blender's own 8-bit file, up to one level of rounding."""
    objects = (
        OBJECTS
        + "    Ball: {primitive: sphere, radius: 0.6, location: [0, 0, 1.8], material: {color: [0.8, 0.3, 0.05]}}\n"
    )
    frames = {}
    for readback in ("memory", "file"):
        e = make_env(tmp_path, objects=objects, observation=THREE_VIEWS, readback=readback)
        try:
            frames[readback] = [observe(e, x=x) for x in (-1.5, 0.0, 1.5)]
        finally:
            e.close()
    for memory, file in zip(frames["memory"], frames["file"]):
        for key in ("color", "gray", "depth"):
            difference = np.abs(memory[key].astype(int) - file[key].astype(int))
            assert difference.max() <= 1, key
            assert (difference > 0).mean() < 0.02, (
                key
            )  # rounding at a handful of pixels, not a shifted or flipped image
        assert memory["color"][5:12].max() > 60  # the ball, near the top: an upside-down copy would differ


def test_readback_option_is_checked(tmp_path):
    with pytest.raises(ValueError, match="unknown readback 'gpu'"):
        make_env(tmp_path, readback="gpu")  # at construction, not at the first render
    e = make_env(tmp_path, render="{engine: workbench}", readback="memory")
    with pytest.raises(ValueError, match="needs the Cycles engine"):
        e.reset(seed=0)
    e.close()


def test_workbench_renders_through_the_file_path(tmp_path):
    e = make_env(tmp_path, render="{engine: workbench}")
    try:
        left, right = observe(e, x=-1.5), observe(e, x=1.5)
        assert centroid_x(right) - centroid_x(left) > 10
    finally:
        e.close()


def test_two_cameras_give_a_dict_of_different_images(tmp_path):
    objects = OBJECTS + "    Top: {camera: perspective, location: [3, 0, 8], look_at: [0, 0, 0], lens: 35}\n"
    observation = """
  cameras:
    front: {camera: Cam, resolution: [32, 32], color: rgb}
    top:   {camera: Top, resolution: [24, 16], color: grayscale}"""
    e = make_env(
        tmp_path,
        objects=objects,
        observation=observation,
        render="{preset: fast, view: {resolution: [64, 48], preset: quality}}",
    )
    try:
        obs = observe(e, x=0.0)
        assert isinstance(obs, dict) and set(obs) == {"front", "top"}
        assert obs["front"].shape == (32, 32, 3) and obs["top"].shape == (16, 24, 1)
        front_gray = obs["front"].mean(axis=2)
        assert obs["top"].max() > 60 and front_gray.max() > 60
        assert not np.array_equal(obs["front"][:16, :24, 0], obs["top"][:, :, 0])
        # the view renders the first camera at the view resolution
        e.render_mode = "rgb_array"
        view = e.render()
        assert view.shape == (48, 64, 3) and view.dtype == np.uint8
        assert view.max() > 60
        assert obs["front"].shape == (32, 32, 3)  # switching back to the observation settings
        assert np.array_equal(e.renderer.render(Frames((e.binding_values(),)))["front"][0], obs["front"])
    finally:
        e.close()


BLEND_SCRIPT = """
import sys, bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
mesh = bpy.data.meshes.new("BallMesh")
import bmesh
bm = bmesh.new(); bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=8, radius=0.6); bm.to_mesh(mesh); bm.free()
mat = bpy.data.materials.new("Glow")
mat.use_nodes = True
bsdf = mat.node_tree.nodes["Principled BSDF"]
bsdf.inputs["Emission Color"].default_value = (1, 1, 1, 1)
bsdf.inputs["Emission Strength"].default_value = 2.0
mesh.materials.append(mat)
ball = bpy.data.objects.new("Ball", mesh); scene.collection.objects.link(ball)
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam")); scene.collection.objects.link(cam)
cam.data.type = "ORTHO"; cam.data.ortho_scale = 6.0
cam.location = (0, -10, 0); cam.rotation_euler = (1.5707963, 0, 0)
lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "SUN")); scene.collection.objects.link(lamp)
scene.camera = cam
if sys.argv[2:] == ["emission"]:  # a material without a Principled BSDF, as a .blend may have
    nodes = mat.node_tree.nodes
    nodes.remove(bsdf)
    emission = nodes.new("ShaderNodeEmission")
    mat.node_tree.links.new(emission.outputs["Emission"], nodes["Material Output"].inputs["Surface"])
if sys.argv[2:] == ["two"]:  # a second scene: the ball again, seen from above
    top = bpy.data.scenes.new("Top")
    top.collection.objects.link(ball); top.collection.objects.link(lamp)
    top_cam = bpy.data.objects.new("TopCam", bpy.data.cameras.new("TopCam")); top.collection.objects.link(top_cam)
    top_cam.data.type = "ORTHO"; top_cam.data.ortho_scale = 6.0; top_cam.location = (0, 0, 10)
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[1], copy=True)
"""


@pytest.fixture(scope="module")
def blend_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("blend") / "fixture.blend"
    subprocess.run([sys.executable, "-c", BLEND_SCRIPT, str(path)], check=True, capture_output=True, timeout=120)
    return path


def test_bound_colour_needs_a_principled_material(tmp_path_factory):
    path = tmp_path_factory.mktemp("blend") / "emission.blend"
    subprocess.run(
        [sys.executable, "-c", BLEND_SCRIPT, str(path), "emission"], check=True, capture_output=True, timeout=120
    )
    with pytest.raises(SpecError, match="material 'Glow' of 'Ball' has none") as info:
        blend_env(path, actors="Ball: {color: [x, 0, 0]}").renderer
    assert info.value.diagnostics[0].path == "actors.Ball.color" and info.value.diagnostics[0].line == 6
    moved = blend_env(path)  # other bindings are fine
    try:
        assert centroid_x(observe(moved, x=1.5)) > centroid_x(observe(moved, x=-1.5)) + 10
    finally:
        moved.close()


@pytest.fixture(scope="module")
def two_scene_blend(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("blend") / "two_scenes.blend"
    subprocess.run([sys.executable, "-c", BLEND_SCRIPT, str(path), "two"], check=True, capture_output=True, timeout=120)
    return path


def blend_env(
    blend: Path, actors: str = "Ball: {location: [x, 0, 0]}", camera: str = "Cam", file_scene: str = ""
) -> VisualEnv:
    text = f"""\
id: BlendTest-v0
scene: {{file: {blend.name}, {file_scene}world: {{color: [0, 0, 0], strength: 0}}}}
state: {{x: {{init: 0.0}}}}
actions: {{discrete: [{{u: 0}}]}}
actors:
{textwrap.indent(actors, "  ")}
observation: {{camera: {camera}, resolution: [48, 32], color: rgb}}
"""
    return VisualEnv(load_spec_text(text, name="blend.yaml", base_dir=blend.parent))


def test_blend_file_objects_are_bound_by_name(blend_file):
    scenes = len(bpy.data.scenes)
    first, second = blend_env(blend_file), blend_env(blend_file)  # the second's objects get renamed inside Blender
    try:
        left, right = observe(first, x=-1.5), observe(second, x=1.5)
        assert centroid_x(right) - centroid_x(left) > 10
        assert centroid_x(observe(first, x=1.5)) == pytest.approx(centroid_x(right), abs=0.5)
        assert first.renderer.object("Ball") is not second.renderer.object("Ball")
    finally:
        first.close()
        second.close()
    assert len(bpy.data.scenes) == scenes


def test_wrong_names_list_what_the_scene_has(blend_file):
    with pytest.raises(SpecError) as info:
        blend_env(blend_file, actors="Bal: {location: [x, 0, 0]}\nLamp: {lens: 50}", camera="Camera").renderer
    message = str(info.value)
    assert "no object 'Bal' in the scene (did you mean 'Ball'?" in message
    assert "Ball" in message and "Cam" in message and "Lamp" in message
    assert "no camera 'Camera'" in message and "did you mean 'Cam'" in message
    assert "'lens' binds a camera's focal length" in message
    assert len(info.value.diagnostics) == 3
    assert {d.path for d in info.value.diagnostics} == {"actors.Bal", "actors.Lamp.lens", "observation.camera"}
    with pytest.raises(SpecError, match="'Lamp' is a light, not a camera"):
        blend_env(blend_file, camera="Lamp").renderer


def test_file_scene_picks_a_scene_of_the_blend(two_scene_blend):
    with pytest.raises(
        SpecError,
        match=r"blend\.yaml:2:.*scene\.file: .*has 2 scenes \((Scene, Top|Top, Scene)\): choose one with scene\.file_scene",
    ):
        blend_env(two_scene_blend).renderer
    top = blend_env(two_scene_blend, camera="TopCam", file_scene="file_scene: Top, ")
    try:
        left, right = observe(top, x=-1.5), observe(top, x=1.5)
        assert centroid_x(right) - centroid_x(left) > 10  # the ball, seen from above, moves along x
    finally:
        top.close()
    with pytest.raises(SpecError, match="no camera 'TopCam'"):
        blend_env(two_scene_blend, camera="TopCam", file_scene="file_scene: Scene, ").renderer
    with pytest.raises(
        SpecError, match=r"blend\.yaml:2:.*scene\.file_scene: .*has no scene 'Tpo' \(did you mean 'Top'\? scenes: "
    ):
        blend_env(two_scene_blend, camera="TopCam", file_scene="file_scene: Tpo, ").renderer


def test_missing_or_bad_blend_file(tmp_path):
    with pytest.raises(SpecError, match="scene file not found") as info:
        blend_env(tmp_path / "missing.blend").renderer
    assert info.value.diagnostics[0].path == "scene.file" and info.value.diagnostics[0].line == 2
    fake = tmp_path / "fake.blend"
    fake.write_text("this is not a blend file\n")
    with pytest.raises(SpecError, match="not a Blender file"):
        blend_env(fake).renderer


def test_missing_texture_image_is_located(tmp_path):
    objects = OBJECTS.replace(
        "material: {color: [0.9, 0.9, 0.9]}", "material: {texture: {type: image, image: nope.png}}"
    )
    with pytest.raises(SpecError, match="image file not found") as info:
        make_env(tmp_path, objects=objects).renderer
    assert info.value.diagnostics[0].path == "scene.objects.Box.material.texture.image"


def test_an_object_parented_to_itself_is_located(tmp_path):
    # a longer loop is in tests/bad_specs/build_parent_loop.yaml; Blender itself raises a TypeError for this one
    with pytest.raises(SpecError, match=r"parents form a loop \(E1 -> E1\)") as info:
        make_env(tmp_path, objects=OBJECTS + "    E1: {empty: true, parent: E1}\n").renderer
    assert info.value.diagnostics[0].path == "scene.objects.E1.parent" and info.value.diagnostics[0].line


def test_same_values_give_identical_frames(env):
    a = observe(env, x=0.3)
    b = observe(env, x=0.3)
    observe(env, x=-1.0)
    c = observe(env, x=0.3)
    assert np.array_equal(a, b) and np.array_equal(a, c)


def test_visibility_binding_hides_the_object(tmp_path):
    e = make_env(tmp_path, actors="Box: {visible: x > 0}")
    try:
        shown = observe(e, x=1.0)
        hidden = observe(e, x=-1.0)
        assert shown.max() > 60 and hidden.max() < 10
    finally:
        e.close()


def test_procedural_textures_and_imported_mesh(tmp_path):
    (tmp_path / "quad.obj").write_text("v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nf 1 2 3 4\n")
    objects = OBJECTS.replace(
        "material: {color: [0.9, 0.9, 0.9]}",
        "material: {texture: {type: checker, scale: 4, colors: [[1, 0, 0], [0, 0, 1]]}}",
    )
    objects += "    Quad: {mesh: quad.obj, location: [2, 0, 0], material: {color: [0, 0, 0], emission: [0, 1, 0], emission_strength: 1.0}}\n"
    objects += "    Ring: {primitive: torus, radius: 0.4, thickness: 0.1, location: [-2, 0, 0], material: {emission: [1, 1, 0]}}\n"
    e = make_env(tmp_path, objects=objects)
    try:
        img = observe(e, x=0.0).astype(int)
        box = img[12:20, 20:28].reshape(-1, 3)
        assert (box[:, 0] > box[:, 2] + 30).any() and (box[:, 2] > box[:, 0] + 30).any()  # both checker colours
        assert img[16, 24 + 16, 1] > 150 and img[16, 24 + 16, 0] < 60  # the imported quad glows green
        assert img[16, 24 - 16 + 3, 0] > 150  # the torus
    finally:
        e.close()


@pytest.mark.parametrize(
    "texture", ["{type: checker, scale: 4, colors: [[1, 1, 1], [0.5, 0.5, 0.5]]}", "{type: noise, scale: 2}"]
)
def test_bound_colour_tints_a_textured_material(tmp_path, texture):
    objects = OBJECTS.replace(
        "material: {color: [0.9, 0.9, 0.9]}", f"material: {{color: [0.9, 0.9, 0.9], texture: {texture}}}"
    )
    e = make_env(tmp_path, objects=objects, actors="Box: {color: [1 - x, 0.05, x]}")
    static = make_env(tmp_path, objects=objects, actors="Box: {location: [0, 0, 0]}")
    try:
        box = (slice(12, 20), slice(20, 28))
        red = observe(e, x=0.0).astype(int)[box].reshape(-1, 3)
        blue = observe(e, x=1.0).astype(int)[box].reshape(-1, 3)
        assert (red[:, 0] > red[:, 2] + 40).all() and (blue[:, 2] > blue[:, 0] + 40).all()
        assert len(np.unique(red[:, 0])) > 1  # still textured: the tint multiplies the texture
        white = make_env(tmp_path, objects=objects, actors="Box: {color: [1, 1, 1]}")
        try:  # a white tint leaves the texture as it is
            assert np.array_equal(observe(white), observe(static))
        finally:
            white.close()
    finally:
        e.close()
        static.close()


def test_create_close_cycles_keep_blender_data_flat(tmp_path):
    def counts():
        return (
            len(bpy.data.objects),
            len(bpy.data.meshes),
            len(bpy.data.materials),
            len(bpy.data.scenes),
            len(bpy.data.cameras),
            len(bpy.data.lights),
            len(bpy.data.worlds),
            len(bpy.data.collections),
        )

    e = make_env(tmp_path, actors="Box: {color: [x, 0, 0]}")
    observe(e, x=0.5)
    path = e.renderer._output.path
    e.close()
    before = counts()
    for i in range(20):
        e = make_env(tmp_path, actors="Box: {color: [x, 0, 0]}")
        observe(e, x=i / 20)
        e.close()
    assert counts() == before
    assert not Path(path).exists()


def test_renderers_in_one_process_do_not_interfere(tmp_path):
    a = make_env(tmp_path)
    b = make_env(tmp_path)
    try:
        left = observe(a, x=-1.5)
        right = observe(b, x=1.5)
        assert centroid_x(right) - centroid_x(left) > 10
        assert np.array_equal(observe(a, x=-1.5), left)
    finally:
        a.close()
        b.close()


@pytest.mark.parametrize(
    "actors",
    [
        "Box: {location: [x, 0, 0]}\nRig: {location: [x, 0, 0]}\nCam: {look_at: [x, 0, 0]}",  # the target follows the rig
        "Rig: {location: [x, 0, 0]}",  # only the rig moves: the camera turns to keep its fixed target
    ],
    ids=["bound-target", "moving-parent"],
)
def test_look_at_aims_a_parented_camera_at_a_world_point(tmp_path, actors):
    # the camera rides on a rig and must keep the box (at its look_at point, in the world) in the middle of the frame
    objects = """\
    Box:  {primitive: cube, size: 1.0, material: {color: [0.9, 0.9, 0.9]}}
    Sun:  {light: sun, strength: 4.0, rotation: [0.8, 0.0, 0.0]}
    Rig:  {empty: true, location: [0, 0, 0]}
    Cam:  {camera: perspective, parent: Rig, location: [3, -10, 2], look_at: [0, 0, 0], lens: 50}
"""
    e = make_env(tmp_path, objects=objects, actors=actors)
    try:
        for x in (0.0, 4.0, -3.0):
            img = observe(e, x=x)
            assert abs(centroid_x(img) - 24) < 2, f"box off-centre with the rig at x={x}"
    finally:
        e.close()
