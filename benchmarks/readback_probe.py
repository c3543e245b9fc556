"""Benchmark: fastest correct way to get a bpy render into a numpy uint8 array.

Runs headless (bpy imported as a module). Builds a tiny scene (red emissive cube,
plane, sun, perspective camera), renders it at 100x100 with Cycles on CPU
(1 sample, 0 bounces, no denoising, 2 fixed threads) and with Workbench, and
prints median / p90 wall time (ms, time.perf_counter) for several
render + readback strategies, followed by correctness checks.

Usage:
    python benchmarks/readback_probe.py [--n 200] [--warmup 10]

Notes on Blender 5.0 behaviour found while writing this (see the report):
* ``bpy.data.images['Render Result'].pixels`` is empty in background mode.
* The compositor Viewer node is not evaluated in background renders
  (render pipeline only requests Viewer outputs when ``not G.background``),
  so ``bpy.data.images['Viewer Node']`` is never created.
* Hence the only way out is a file; /dev/shm + uncompressed BMP/TGA parsed
  with numpy is the fastest.
"""

from __future__ import annotations

import argparse
import math
import os
import struct
import tempfile
import time

import numpy as np

import bpy

SHM = "/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir()
RES = 100


# --------------------------------------------------------------------------- scene
def build_scene(engine: str = "CYCLES", res: int = RES) -> bpy.types.Scene:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    r = scene.render
    r.engine = engine
    r.resolution_x = r.resolution_y = res
    r.resolution_percentage = 100
    r.threads_mode = "FIXED"
    r.threads = 2
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    if engine == "CYCLES":
        c = scene.cycles
        c.device = "CPU"
        c.samples = 1
        c.use_adaptive_sampling = False
        c.use_denoising = False
        c.max_bounces = 0
        c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = 0
        c.volume_bounces = c.transparent_max_bounces = 0
    elif engine == "BLENDER_WORKBENCH":
        scene.display.shading.light = "FLAT"
        scene.display.shading.color_type = "MATERIAL"

    def link(name, data):
        ob = bpy.data.objects.new(name, data)
        scene.collection.objects.link(ob)
        return ob

    import bmesh

    # red emission cube in the centre
    me = bpy.data.meshes.new("cube")
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1.0)
    bm.to_mesh(me)
    bm.free()
    link("cube", me)
    me.materials.append(_emission_material("red", (1.0, 0.0, 0.0)))
    # grey diffuse ground plane
    pm = bpy.data.meshes.new("plane")
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=5.0)
    bm.to_mesh(pm)
    bm.free()
    plane = link("plane", pm)
    plane.location.z = -0.5
    sun = link("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = 1.0
    sun.rotation_euler = (0.5, 0.2, 0.0)
    cam = link("cam", bpy.data.cameras.new("cam"))
    cam.location = (0.0, -4.0, 3.0)
    cam.rotation_euler = (math.radians(53.13), 0.0, 0.0)  # looks at the origin
    scene.camera = cam
    world = bpy.data.worlds.new("world")
    world.color = (0.0, 0.0, 0.0)
    bg = world.node_tree.nodes.get("Background")
    if bg is not None:
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    scene.world = world
    return scene


def _emission_material(name, rgb):
    mat = bpy.data.materials.new(name)
    mat.diffuse_color = (*rgb, 1.0)  # used by Workbench
    # Do not treat the emitter as a light source: with 1 spp and light sampling
    # split between sun and emitter the ground plane becomes salt-and-pepper noise.
    mat.cycles.emission_sampling = "NONE"
    nt = mat.node_tree
    nt.nodes.clear()
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (*rgb, 1.0)
    em.inputs["Strength"].default_value = 1.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def fast_settings(scene, persistent=True):
    """Knobs that measurably cut per-render cost (see knob table)."""
    r = scene.render
    r.use_persistent_data = persistent
    r.use_compositing = False
    r.use_sequencer = False
    if scene.render.engine == "CYCLES":
        scene.cycles.pixel_filter_type = "BOX"
        scene.cycles.use_light_tree = False


def set_output(scene, path, fmt, mode="RGB", **kw):
    s = scene.render.image_settings
    s.media_type = "IMAGE"
    s.file_format = fmt
    s.color_mode = mode
    for k, v in kw.items():
        setattr(s, k, v)
    scene.render.filepath = path
    scene.render.use_file_extension = False  # write exactly to `path`


# --------------------------------------------------------------------------- readers
def read_bmp(path: str) -> np.ndarray:
    """Uncompressed 8/24/32-bit BMP -> uint8 (H,W) / (H,W,3) / (H,W,4), top row first, RGB."""
    buf = np.fromfile(path, dtype=np.uint8)
    off, = struct.unpack_from("<I", buf, 10)
    hdr_size, w, h, _planes, bpp, comp = struct.unpack_from("<IiiHHI", buf, 14)
    if comp not in (0, 3):
        raise ValueError(f"compressed BMP not supported (compression={comp})")
    stride = ((w * bpp + 31) // 32) * 4  # rows are padded to 4 bytes
    rows = buf[off : off + stride * abs(h)].reshape(abs(h), stride)
    if h > 0:  # positive height = bottom-up storage
        rows = rows[::-1]
    if bpp == 8:
        img = rows[:, :w]
        n_pal = struct.unpack_from("<I", buf, 46)[0] or 256
        pal = buf[14 + hdr_size : 14 + hdr_size + 4 * n_pal].reshape(n_pal, 4)
        if not (np.array_equal(pal[:, 0], np.arange(n_pal)) and np.array_equal(pal[:, 0], pal[:, 2])):
            img = pal[img][..., 2::-1]  # non-identity palette -> RGB
        return np.ascontiguousarray(img)
    ch = bpp // 8
    img = rows[:, : w * ch].reshape(abs(h), w, ch)
    order = [2, 1, 0] if ch == 3 else [2, 1, 0, 3]  # BGR(A) -> RGB(A)
    return img[:, :, order]  # fancy indexing makes a contiguous copy


def read_tga_raw(path: str) -> np.ndarray:
    """Uncompressed TGA (type 2 truecolor / type 3 gray) -> uint8, top row first, RGB."""
    buf = np.fromfile(path, dtype=np.uint8)
    id_len, cmap_type, img_type = buf[0], buf[1], buf[2]
    if cmap_type != 0 or img_type not in (2, 3):
        raise ValueError(f"unsupported TGA type {img_type}")
    w, h, bpp, desc = struct.unpack_from("<HHBB", buf, 12)
    ch = bpp // 8
    start = 18 + int(id_len)
    img = buf[start : start + w * h * ch].reshape(h, w, ch)
    if not desc & 0x20:  # bit 5 clear = bottom-left origin
        img = img[::-1]
    if ch == 1:
        return np.ascontiguousarray(img[:, :, 0])
    return img[:, :, [2, 1, 0] if ch == 3 else [2, 1, 0, 3]]


def read_exr_uncompressed(path: str) -> dict[str, np.ndarray]:
    """Single-part scanline OpenEXR with compression NONE -> {channel: float32 (H,W)}."""
    data = open(path, "rb").read()
    magic, flags = struct.unpack_from("<iI", data, 0)
    if magic != 20000630 or flags & 0x1200:  # multipart / deep not supported
        raise ValueError("not a single-part scanline EXR")
    pos, attrs = 8, {}
    while data[pos] != 0:
        name_end = data.index(b"\0", pos)
        type_end = data.index(b"\0", name_end + 1)
        size, = struct.unpack_from("<i", data, type_end + 1)
        attrs[data[pos:name_end].decode()] = data[type_end + 5 : type_end + 5 + size]
        pos = type_end + 5 + size
    pos += 1
    if attrs["compression"][0] != 0:
        raise ValueError("only compression NONE supported")
    chans, p, cl = [], 0, attrs["channels"]
    while cl[p] != 0:
        e = cl.index(b"\0", p)
        chans.append((cl[p:e].decode(), struct.unpack_from("<i", cl, e + 1)[0]))
        p = e + 17
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    dt = {1: np.float16, 2: np.float32, 0: np.uint32}
    line_bytes = sum(w * np.dtype(dt[t]).itemsize for _, t in chans)
    raw = np.frombuffer(data, np.uint8, count=h * (8 + line_bytes), offset=pos + 8 * h)
    raw = raw.reshape(h, 8 + line_bytes)[:, 8:]  # drop (y, size) per scanline
    out, o = {}, 0
    for name, t in chans:  # channels are stored alphabetically, line by line
        nb = w * np.dtype(dt[t]).itemsize
        out[name] = raw[:, o : o + nb].copy().view(dt[t]).astype(np.float32)
        o += nb
    return out  # row 0 = top (INCREASING_Y)


def read_pil(path: str) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im)


# --------------------------------------------------------------------------- timing
def bench(fn, n, warmup):
    for _ in range(warmup):
        fn()
    ts = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        fn()
        ts[i] = time.perf_counter() - t0
    ts *= 1e3
    return float(np.median(ts)), float(np.percentile(ts, 90))


class Quiet:
    """Silence Blender's unconditional "Saved: '...'" stdout line (fd-level)."""

    def __enter__(self):
        self._null = os.open(os.devnull, os.O_WRONLY)
        self._saved = os.dup(1)
        os.dup2(self._null, 1)

    def __exit__(self, *exc):
        os.dup2(self._saved, 1)
        os.close(self._saved)
        os.close(self._null)


def render(write=False):
    bpy.ops.render.render(write_still=write)


# --------------------------------------------------------------------------- main
def knob_table(n, warmup, rows):
    scene = build_scene("CYCLES")
    cube = bpy.data.objects["cube"]
    rng = np.random.default_rng(0)

    def moved():
        cube.location.x = rng.uniform(-0.3, 0.3)
        render()

    def add(label, fn=render):
        rows.append(("knob", label, *bench(fn, n, warmup)))

    add("cycles default (render only)")
    add("cycles default, cube moved every frame", moved)
    r, c = scene.render, scene.cycles
    r.use_compositing = False
    r.use_sequencer = False
    add("+ use_compositing=False, use_sequencer=False")
    c.pixel_filter_type = "BOX"
    add("+ pixel_filter_type=BOX")
    c.use_light_tree = False
    add("+ use_light_tree=False")
    r.use_lock_interface = True
    add("+ use_lock_interface=True")
    r.use_lock_interface = False
    c.use_auto_tile = False
    add("+ use_auto_tile=False")
    c.use_auto_tile = True
    r.film_transparent = True
    add("+ film_transparent=True")
    r.film_transparent = False
    r.threads = 1
    add("+ threads=1 (instead of 2)")
    r.threads = 2
    r.use_persistent_data = True
    add("+ use_persistent_data=True")
    add("+ use_persistent_data=True, cube moved", moved)


def readback_table(engine, n, warmup, rows):
    """All strategies measured round-robin (shuffled each round) so that they see
    the same machine load; per-case output settings are applied outside the timer."""
    scene = build_scene(engine)
    fast_settings(scene)
    tag = "cycles" if engine == "CYCLES" else "workbench"
    cases = []  # (label, setup, timed_fn)

    def file_case(label, fmt, mode, reader, ext, **kw):
        path = os.path.join(SHM, f"rb_probe_{tag}_{len(cases)}.{ext}")

        def fn():
            render(True)
            return reader(path)

        cases.append((label, lambda: set_output(scene, path, fmt, mode, **kw), fn))

    cases.append(("render only (floor, fast settings)", lambda: None, render))
    file_case("write BMP RGB + numpy parse", "BMP", "RGB", read_bmp, "bmp")
    if engine == "CYCLES":
        file_case("write BMP BW  + numpy parse", "BMP", "BW", read_bmp, "bmp")
        file_case("write BMP RGB + PIL", "BMP", "RGB", read_pil, "bmp")
        file_case("write TGA raw RGB + numpy parse", "TARGA_RAW", "RGB", read_tga_raw, "tga")
        file_case("write PNG (compression 0) + PIL", "PNG", "RGB", read_pil, "png", compression=0, color_depth="8")
        file_case("write EXR float32 NONE + numpy parse", "OPEN_EXR", "RGB", read_exr_uncompressed, "exr",
                  color_depth="32", exr_codec="NONE")

        # render() then Render Result.save_render() (uses the scene's image settings)
        sr_path = os.path.join(SHM, "rb_probe_saverender.bmp")
        def save_render():
            render(False)
            bpy.data.images["Render Result"].save_render(sr_path, scene=scene)
            return read_bmp(sr_path)

        cases.append(("render + RenderResult.save_render BMP + numpy",
                      lambda: set_output(scene, sr_path, "BMP", "RGB"), save_render))

        # file -> bpy.data.images.load -> pixels.foreach_get (pure-bpy path)
        ld_path = os.path.join(SHM, "rb_probe_load.bmp")
        buf = np.empty(RES * RES * 4, np.float32)

        def via_bpy_image():
            render(True)
            img = bpy.data.images.load(ld_path)
            img.pixels.foreach_get(buf)
            bpy.data.images.remove(img)
            return (buf.reshape(RES, RES, 4)[::-1, :, :3] * 255 + 0.5).astype(np.uint8)

        cases.append(("write BMP + images.load + pixels.foreach_get",
                      lambda: set_output(scene, ld_path, "BMP", "RGB"), via_bpy_image))

    rng = np.random.default_rng(0)
    times = np.zeros((len(cases), n))
    for it in range(warmup + n):
        for k in rng.permutation(len(cases)):
            label, setup, fn = cases[k]
            setup()
            t0 = time.perf_counter()
            fn()
            if it >= warmup:
                times[k, it - warmup] = time.perf_counter() - t0
    times *= 1e3
    for k, (label, _, _) in enumerate(cases):
        rows.append((tag, label, float(np.median(times[k])), float(np.percentile(times[k], 90))))


def depth_demo(n, warmup, rows):
    """RGB (write_still BMP) + metric depth (compositor File Output -> EXR float32)."""
    scene = build_scene("CYCLES")
    fast_settings(scene)
    scene.render.use_compositing = True  # compositor must run for the File Output node
    scene.view_layers[0].use_pass_z = True
    ng = bpy.data.node_groups.new("probe_depth", "CompositorNodeTree")
    scene.compositing_node_group = ng
    rl = ng.nodes.new("CompositorNodeRLayers")
    out = ng.nodes.new("NodeGroupOutput")
    ng.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    ng.links.new(rl.outputs["Image"], out.inputs["Image"])
    fo = ng.nodes.new("CompositorNodeOutputFile")
    fo.directory = SHM + "/"
    fo.file_name = "rb_probe_depth_"
    fo.file_output_items.new("FLOAT", "Z")
    fmt = fo.format
    fmt.media_type = "IMAGE"  # default is MULTI_LAYER_IMAGE
    fmt.file_format = "OPEN_EXR"
    fmt.exr_codec = "NONE"
    fmt.color_depth = "32"
    fmt.color_mode = "BW"  # single channel, stored as 'V'
    ng.links.new(rl.outputs["Depth"], fo.inputs["Z"])
    rgb_path = os.path.join(SHM, "rb_probe_rgbd.bmp")
    set_output(scene, rgb_path, "BMP", "RGB")  # also disables file extensions
    depth_path = os.path.join(SHM, "rb_probe_depth_Z")  # directory + file_name + item name

    def fn():
        render(True)
        return read_bmp(rgb_path), read_exr_uncompressed(depth_path)["V"]

    rows.append(("cycles", "RGB BMP + depth EXR (File Output node)", *bench(fn, n, warmup)))
    rgb, z = fn()
    return z


def check_background_buffers():
    """Render Result / Viewer Node availability in background mode."""
    scene = build_scene("CYCLES")
    ng = bpy.data.node_groups.new("probe_comp", "CompositorNodeTree")
    scene.compositing_node_group = ng
    scene.render.use_compositing = True
    rl = ng.nodes.new("CompositorNodeRLayers")
    viewer = ng.nodes.new("CompositorNodeViewer")
    ng.links.new(rl.outputs["Image"], viewer.inputs["Image"])
    ng.nodes.active = viewer
    render()
    rr = bpy.data.images["Render Result"]
    print(f"  bpy.app.background = {bpy.app.background}")
    print(f"  Render Result after render: size={tuple(rr.size)} len(pixels)={len(rr.pixels)} has_data={rr.has_data}")
    print(f"  'Viewer Node' image exists (viewer only): {'Viewer Node' in bpy.data.images}")
    out = ng.nodes.new("NodeGroupOutput")
    ng.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    ng.links.new(rl.outputs["Image"], out.inputs["Image"])
    render()
    print(f"  'Viewer Node' image exists (viewer + group output): {'Viewer Node' in bpy.data.images}")


def correctness():
    scene = build_scene("CYCLES")
    fast_settings(scene)
    # marker: small green emissive cube in the upper-left of the view
    cam = scene.camera
    bpy.context.view_layer.update()  # make cam.matrix_world valid
    me = bpy.data.meshes["cube"].copy()
    me.materials.clear()
    me.materials.append(_emission_material("green", (0.0, 1.0, 0.0)))
    mk = bpy.data.objects.new("marker", me)
    mk.scale = (0.15, 0.15, 0.15)
    scene.collection.objects.link(mk)
    # place it along the ray through normalized view coords (0.15, 0.85) at depth 3
    frame = cam.data.view_frame(scene=scene)  # corners in camera space
    tl = [v for v in frame if v.x < 0 and v.y > 0][0]
    br = [v for v in frame if v.x > 0 and v.y < 0][0]
    import mathutils

    p = mathutils.Vector((tl.x + 0.15 * (br.x - tl.x), tl.y + 0.15 * (br.y - tl.y), tl.z))
    mk.location = cam.matrix_world @ (p * (3.0 / -p.z))
    path = os.path.join(SHM, "rb_probe_check.bmp")
    set_output(scene, path, "BMP", "RGB")
    with Quiet():
        render(True)
    rgb = read_bmp(path)
    pil = read_pil(path)
    print(f"  BMP numpy parse == PIL: {np.array_equal(rgb, pil)}  shape={rgb.shape} dtype={rgb.dtype}")
    g = np.argwhere((rgb[:, :, 1] > 200) & (rgb[:, :, 0] < 50))
    print(f"  green marker pixels: {len(g)}, centroid (row, col) = {g.mean(0).round(1)} (expect ~(15, 15))")
    red = rgb[(rgb[:, :, 0] > 200) & (rgb[:, :, 1] < 50)]
    print(f"  red emission pixels: {len(red)}, median value = {np.median(red, 0)} (expect (255, 0, 0))")
    tga = os.path.join(SHM, "rb_probe_check.tga")
    set_output(scene, tga, "TARGA_RAW", "RGB")
    with Quiet():
        render(True)
    print(f"  TGA numpy parse == BMP (same seed): {np.array_equal(read_tga_raw(tga), rgb)}")
    set_output(scene, path, "BMP", "BW")
    with Quiet():
        render(True)
    bw = read_bmp(path).astype(np.int16)
    f = rgb.astype(np.float64)
    for name, wts in (("Rec.709 (0.2126, 0.7152, 0.0722)", (0.2126, 0.7152, 0.0722)),
                      ("Rec.601 (0.299, 0.587, 0.114)", (0.299, 0.587, 0.114))):
        mine = np.clip(np.round(f @ np.array(wts)), 0, 255).astype(np.int16)
        d = np.abs(mine - bw)
        print(f"  BW vs numpy luma {name} on sRGB bytes: max|diff|={d.max()} mean|diff|={d.mean():.3f}")
    lin = np.where(f <= 10.31475, f / 3294.6, ((f / 255 + 0.055) / 1.055) ** 2.4)  # sRGB -> linear
    y = lin @ np.array((0.2126, 0.7152, 0.0722))
    enc = np.where(y <= 0.0031308, 12.92 * y, 1.055 * y ** (1 / 2.4) - 0.055)
    d = np.abs(np.round(enc * 255).astype(np.int16) - bw)
    print(f"  BW vs numpy Rec.709 luminance in LINEAR light, re-encoded sRGB: "
          f"max|diff|={d.max()} mean|diff|={d.mean():.3f} exact={np.mean(d == 0):.1%}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--skip-knobs", action="store_true")
    args = ap.parse_args()

    rows = []
    with Quiet():
        if not args.skip_knobs:
            knob_table(args.n, args.warmup, rows)
        readback_table("CYCLES", args.n, args.warmup, rows)
        readback_table("BLENDER_WORKBENCH", args.n, args.warmup, rows)
        z = depth_demo(args.n, args.warmup, rows)

    print(f"\nbpy {bpy.app.version_string}, {RES}x{RES}, n={args.n}, warmup={args.warmup}, output dir {SHM}")
    print(f"{'group':10s} {'method':50s} {'median ms':>10s} {'p90 ms':>8s}")
    for grp, label, med, p90 in rows:
        print(f"{grp:10s} {label:50s} {med:10.2f} {p90:8.2f}")
    print(f"\nDepth (metres) centre={z[50, 50]:.3f} bottom={z[97, 50]:.3f} top(sky)={z[2, 50]:.3g}")
    print("\nBackground-mode buffers:")
    check_background_buffers()
    print("\nCorrectness (Cycles, fast settings, BMP):")
    correctness()
    for name in os.listdir(SHM):
        if name.startswith("rb_probe_"):
            os.remove(os.path.join(SHM, name))


if __name__ == "__main__":
    main()
