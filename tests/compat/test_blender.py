"""What visualenv relies on in Blender and Cycles beyond their API (visualenv.compat.blender), checked against the
installed bpy: each test names the part it checks, and fails when bpy no longer behaves as that part expects."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visualenv.compat import blender as compat  # noqa: E402
from visualenv.compat import glibc  # noqa: E402

pytestmark = pytest.mark.blender

ROOT = Path(__file__).parents[2]


def run_python(code: str, env: dict[str, str] | None = None) -> dict:
    """Run `code` in a fresh Python (Blender state that is process-wide stays there); its last stdout line as JSON."""
    import os

    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def cycles_scene(name: str, size: int) -> tuple:
    scene = bpy.data.scenes.new(name)
    scene.render.engine = "CYCLES"
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.cycles.samples = 1
    scene.cycles.use_denoising = False
    data = bpy.data.cameras.new(name)
    camera = bpy.data.objects.new(name, data)
    scene.collection.objects.link(camera)
    scene.camera = camera
    return scene, camera, data


def test_the_installed_bpy_is_one_every_part_was_checked_against():
    assert compat.bpy_version() == bpy.app.version_string.split()[0]
    assert compat.bpy_version() in compat.CHECKED_BPY, (
        f"bpy {compat.bpy_version()}: check every part of visualenv/compat/blender.py against it (this file's tests), then add it to CHECKED_BPY"
    )


def test_an_unchecked_bpy_is_told_once_per_part(monkeypatch):
    monkeypatch.setattr(compat, "bpy_version", lambda: "9.9.9")
    monkeypatch.setattr(compat, "_warned", set())
    with pytest.warns(RuntimeWarning, match="checked against bpy 5.0.1, not 9.9.9"):
        assert not compat.check_bpy("part")
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not compat.check_bpy("part")


def test_a_custom_camera_compiles_through_blenders_operator_with_bpys_own_packages():
    """Part: bpy's bundled Python packages on sys.path (oslquery), Blender's Update Custom Camera operator."""
    scene, camera, data = cycles_scene("visualenv-compat-osl", 8)
    text = bpy.data.texts.new("visualenv-compat.osl")
    try:
        text.write(
            "shader probe(int cols = 3, float half_w = 0.5, output point position = 0, output vector direction = 0,"
            " output color throughput = 1) { direction = vector(0, 0, 1); }"
        )
        data.type, data.custom_mode, data.custom_shader = "CUSTOM", "INTERNAL", text
        compat.compile_camera_shader(camera, scene)
        assert dict(data.cycles_custom) == {"cols": 3, "half_w": 0.5}
        import oslquery  # noqa: F401 - on the path now

        text.clear()
        text.write("shader probe( not osl")
        with pytest.raises(RuntimeError, match="compilation failed"):
            compat.compile_camera_shader(camera, scene)
    finally:
        bpy.data.scenes.remove(scene)
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(data)
        bpy.data.texts.remove(text)


def test_bpy_does_not_put_its_bundled_packages_on_the_path_itself():
    """Part: bpy's bundled packages on sys.path. Fails when bpy finds ``oslquery`` on its own (the part is then not needed)."""
    found = run_python("""
        import importlib.util, json
        import bpy
        print(json.dumps({"oslquery": importlib.util.find_spec("oslquery") is not None}))
    """)
    assert found == {"oslquery": False}


def test_a_spawned_process_drops_the_script_folders_it_inherits_and_bpy_adds_them_back():
    """Part: script folders inherited from a process that imported bpy, which would shadow the bpy module."""
    scripts = next(p for p in sys.path if "/bpy/" in p and "/scripts" in p)  # bpy put its script folders on the path
    result = run_python(f"""
        import json, sys
        sys.path.insert(0, {scripts!r})
        from visualenv.compat.blender import drop_inherited_script_paths
        drop_inherited_script_paths()
        dropped = {scripts!r} not in sys.path
        import bpy
        print(json.dumps({{"dropped": dropped, "back": {scripts!r} in sys.path}}))
    """)
    assert result == {"dropped": True, "back": True}


def test_cycles_render_method_can_be_wrapped_to_read_its_result():
    """Part: Cycles' render method wrapped (the in-memory readback)."""
    pixels: list[int] = []

    def after(engine) -> None:
        pixels.append(len(engine.get_result().layers[0].passes["Combined"].rect))

    scene, camera, data = cycles_scene("visualenv-compat-wrap", 8)
    try:
        assert compat.wrap_cycles_render(after)
        bpy.ops.render.render(scene=scene.name)
        compat.unwrap_cycles_render(after)
        bpy.ops.render.render(scene=scene.name)
    finally:
        compat.unwrap_cycles_render(after)
        bpy.data.scenes.remove(scene)
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(data)
    assert pixels == [64]


def test_cycles_update_and_render_can_be_marked_and_the_marks_stopped():
    """Part: Cycles' update and render methods wrapped (bench --phases: where Blender's depsgraph ends, Cycles' sync starts)."""
    moments: list[str] = []
    scene, camera, data = cycles_scene("visualenv-compat-marks", 8)
    stop = compat.mark_cycles_calls(moments.append)
    try:
        assert stop is not None
        bpy.ops.render.render(scene=scene.name)
        stop()
        bpy.ops.render.render(scene=scene.name)
    finally:
        if stop is not None:
            stop()
        bpy.data.scenes.remove(scene)
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(data)
    assert moments == list(compat.CYCLES_MARKS)


def random_objects(rng: np.random.Generator, count: int, mode: str, scene) -> list:
    objects = []
    for _ in range(count):
        obj = bpy.data.objects.new("visualenv-compat-matrix", None)
        scene.collection.objects.link(obj)
        obj.rotation_mode = mode
        obj.location = rng.uniform(-50, 50, 3)
        if mode == "QUATERNION":
            obj.rotation_quaternion = rng.uniform(-2, 2, 4)  # not normalised: Blender normalises it
        else:
            obj.rotation_euler = rng.uniform(-7, 7, 3)
        obj.scale = rng.uniform(0.1, 3, 3)
        objects.append(obj)
    return objects


def test_numpy_composes_object_matrices_as_blender_to_the_bit():
    """Part: Blender's matrix arithmetic (BKE_object_to_mat4, eulO_to_mat3, quat_to_mat3, mul_m4_m4m4's SSE order):
    instances posed from numpy stand where Blender would put the objects, to the bit."""
    rng = np.random.default_rng(0)
    scene = bpy.data.scenes.new("visualenv-compat-matrix")
    try:
        for mode in ("XYZ", "QUATERNION"):
            objects = random_objects(rng, 100, mode, scene)
            for obj in objects:
                rotation = (
                    np.array([obj.rotation_quaternion])
                    if mode == "QUATERNION"
                    else np.array([obj.rotation_euler], dtype=np.float32)
                )
                basis = compat.basis_matrices(
                    np.array([obj.location], dtype=np.float32), rotation, np.array([obj.scale], dtype=np.float32)
                )
                assert np.array_equal(basis[0], np.array(obj.matrix_basis, dtype=np.float32)), (
                    mode,
                    obj.rotation_euler[:],
                )
            parents, children = objects[::2], objects[1::2]
            for parent, child in zip(parents, children):
                child.parent = parent
                child.matrix_parent_inverse.identity()
            scene.view_layers[0].update()
            for parent, child in zip(parents, children):
                world = compat.mul_m4_m4m4(
                    np.array(parent.matrix_world, dtype=np.float32), np.array(child.matrix_basis, dtype=np.float32)
                )
                assert np.array_equal(world, np.array(child.matrix_world, dtype=np.float32)), mode
            # numpy's plain product rounds otherwise somewhere among these: the order of sums is what matches
            plain = [
                np.array(p.matrix_world, dtype=np.float32) @ np.array(c.matrix_basis, dtype=np.float32)
                for p, c in zip(parents, children)
            ]
            assert any(
                not np.array_equal(a, np.array(c.matrix_world, dtype=np.float32)) for a, c in zip(plain, children)
            )
            bpy.data.batch_remove(objects)
    finally:
        bpy.data.scenes.remove(scene)


FRAMES = """
    import json
    import bpy
    from visualenv.compat.glibc import bytes_in_use

    def in_use():
        return bytes_in_use() / 2**20

    def scene(size):
        s = bpy.data.scenes.new("visualenv-compat-frames")
        s.render.engine = "CYCLES"
        s.render.resolution_x = s.render.resolution_y = size
        s.cycles.samples = 1
        s.cycles.use_denoising = False
        data = bpy.data.cameras.new("c")
        camera = bpy.data.objects.new("c", data)
        s.collection.objects.link(camera)
        s.camera = camera
        return s, camera, data

    def remove(s, camera, data):
        bpy.data.scenes.remove(s)
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(data)

    def render_and_remove():
        big = scene(1500)
        bpy.ops.render.render(scene=big[0].name)
        if RELEASE:
            from visualenv.compat.blender import release_render_result
            release_render_result(big[0])
        remove(*big)

    figures = {"before": in_use()}
    render_and_remove()
    figures["removed"] = in_use()
    print(json.dumps(figures))
"""


@pytest.mark.skipif(
    glibc.version() is None or glibc.version() < (2, 33), reason="counts malloc's bytes with glibc's mallinfo2"
)
@pytest.mark.parametrize("release", [False, True])
def test_blender_keeps_a_removed_scenes_last_frame_unless_it_is_released(release):
    """Part: render results. A 1500x1500 frame (34 MiB in float RGBA) outlives its scene, unless a last tiny frame
    replaces it before removal (release_render_result). Counted as malloc's bytes in use: resident memory keeps
    what glibc keeps, which differs across machines."""
    figures = run_python(FRAMES.replace("RELEASE", str(release)))
    kept = figures["removed"] - figures["before"]
    if release:
        assert abs(kept) < 10, figures
    else:
        assert kept > 25, figures


def test_renderers_reuse_the_names_of_closed_scenes():
    """Part: render results, one per scene name: a closed env's scene name is the next env's."""
    import gc

    import visualenv

    gc.collect()  # an earlier test's env collected meanwhile (a vector env closes itself then) would free a name
    gc.disable()
    envs = []
    try:
        for _ in range(2):
            envs.append(visualenv.make("VisualCartPole-v0"))
            envs[-1].reset(seed=0)
        first, second = (env.unwrapped.renderer.scene.name for env in envs)
        envs.pop(0).close()
        envs.append(visualenv.make("VisualCartPole-v0"))
        envs[-1].reset(seed=0)
        assert first.startswith("visualenv-scene-") and second != first
        assert envs[-1].unwrapped.renderer.scene.name == first
    finally:
        gc.enable()
        for env in envs:
            env.close()


HOOK = """
    import json, os, shutil, tempfile
    from pathlib import Path
    import bpy, _cycles
    from visualenv.compat import blender as compat

    addon = compat.cycles_addon()
    ptx = compat.source_ptx("sm_90", addon / "lib")
    cached = compat.cached_kernel("sm_90", ptx, compat.bpy_version())
    cached.parent.mkdir(parents=True)
    cached.write_bytes(b"a stand-in: no GPU loads it here")
    folder = compat.use_cached_kernels()

    osl = Path(tempfile.mkdtemp()) / "probe.osl"
    osl.write_text('#include "stdcycles.h"\\nshader probe(output color c = 0) { c = color(1); }')
    def compiles():
        return bool(_cycles.osl_compile(str(osl), str(osl.with_suffix(".oso"))))

    through = compiles()
    blind = Path(tempfile.mkdtemp())  # the same folder without Cycles' shader headers
    for entry in folder.iterdir():
        if entry.name != "shader":
            (blind / entry.name).symlink_to(entry)
    compat.point_cycles_at(blind)
    without = compiles()
    compat.point_cycles_at(folder)
    print(json.dumps({"folder": str(folder), "kernel": str((folder / "lib" / "kernel_sm_90.cubin.zst").resolve()),
                      "cached": str(cached), "compiles": through, "without_headers": without, "again": compiles(),
                      "links": sorted(p.name for p in (folder / "lib").iterdir()), "lib": sorted(p.name for p in (addon / "lib").iterdir())}))
"""


def test_cycles_reads_the_kernels_cached_outside_site_packages(tmp_path):
    """Part: the CUDA kernel cache. A cached sm_90 binary is linked where Cycles looks first (path_get("lib/...")), in a
    folder that is the add-on's seen through links, and Cycles reads that folder (shown by its OSL compiler, which
    reads "shader" the same way: blind without the folder's headers). That CUDA loads the binary needs a GPU."""
    figures = run_python(HOOK, {"XDG_CACHE_HOME": str(tmp_path)})
    assert Path(figures["folder"]).is_relative_to(tmp_path / "visualenv" / "cycles")
    assert figures["kernel"] == figures["cached"]
    assert figures["links"] == sorted([*figures["lib"], "kernel_sm_90.cubin.zst"])
    assert (figures["compiles"], figures["without_headers"], figures["again"]) == (True, False, True)


def test_a_uv_spheres_faces_come_in_one_order_in_every_process():
    """Part "face order": bmesh's UV sphere lists its faces in an order that varies between processes (so Blender's
    vertex normals, summed in face order, varied in their last bits); sort_faces makes it one order. Two processes
    show the variation (the same faces, listed otherwise) and that sorted faces are the same."""
    code = """
        import json
        import bpy  # noqa: F401 - bmesh comes with it
        import bmesh
        from visualenv.compat.blender import sort_faces
        made = []
        for _ in range(3):
            bm = bmesh.new()
            bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=1.0)
            bm.verts.index_update()
            made.append([[v.index for v in f.verts] for f in bm.faces])
        sort_faces(bm)
        print(json.dumps({"made": made, "sorted": [[v.index for v in f.verts] for f in bm.faces]}))
    """
    runs = [run_python(code) for _ in range(3)]
    orders = {json.dumps(made) for run in runs for made in run["made"]}
    assert (
        len({json.dumps(sorted(map(tuple, json.loads(order)))) for order in orders}) == 1
    )  # the same faces every time
    assert len(orders) > 1, "create_uvsphere's face order no longer varies: sort_faces may no longer be needed"
    assert len({json.dumps(run["sorted"]) for run in runs}) == 1
    faces = runs[0]["sorted"]
    assert faces == sorted(faces, key=sorted)
