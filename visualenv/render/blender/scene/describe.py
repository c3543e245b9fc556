"""What a .blend holds, as a spec writer needs it; run in a child process (see :mod:`visualenv.render.blender.scene.blendfile`).

Opening a user's file can crash Blender, so this module is the body of a reader process: it reads
requests (one JSON line: ``{"path": ...}``) on stdin and answers each with one JSON line on the
stdout it started with (Blender's own messages go to stderr). Scripts in the file never run (:mod:`.autorun`).
"""

from __future__ import annotations

import json
import os
import select
import sys
from typing import Any

import bpy

from visualenv.render.blender.runtime.autorun import turn_autorun_off
from visualenv.render.blender.scene.user_file import animated_fcurves, constraint_sets

_R = 4  # decimals of the numbers reported
#: seconds without a request after which the reader exits (a process that builds once keeps no idle Blender)
IDLE_EXIT = 30.0


def _vec(v: Any) -> list[float]:
    return [round(float(x), _R) for x in v]


def _bindable(mat: Any) -> bool:
    """Whether a bound colour reaches the render: the material has a Principled BSDF (see materials.color_writer)."""
    return (
        mat is not None and mat.node_tree is not None and any(n.type == "BSDF_PRINCIPLED" for n in mat.node_tree.nodes)
    )


def _animated(obj: Any) -> list[str]:
    """The channels of `obj` that the file animates: keyframes/NLA, drivers, constraints."""
    out = []
    for owner, prefix in ((obj, ""), (obj.data, "data.")):
        anim = getattr(owner, "animation_data", None)
        if anim is None:
            continue
        paths = sorted({fc.data_path for fc in animated_fcurves(anim)})
        out += [f"{prefix}{p} (keyframes)" for p in paths]
        out += [f"{prefix}{p} (driver)" for p in sorted({fc.data_path for fc in anim.drivers})]
    out += [
        f"{'/'.join(sorted(constraint_sets(c.type)))} (constraint '{c.name}', {c.type})"
        for c in obj.constraints
        if c.enabled
    ]
    return out


def _overrides(scene: Any) -> list[str]:
    """The file's settings that differ from what visualenv renders with (the spec wins)."""
    r, vs, c = scene.render, scene.view_settings, scene.cycles
    found = []

    def differs(label: str, value: Any, ours: Any) -> None:
        if value != ours:
            found.append(f"{label}: {value!r} (visualenv: {ours!r})")

    differs("engine", r.engine, "CYCLES")
    differs("output", r.image_settings.media_type, "IMAGE")
    differs("resolution percentage", r.resolution_percentage, 100)
    differs("pixel aspect", [round(r.pixel_aspect_x, 3), round(r.pixel_aspect_y, 3)], [1.0, 1.0])
    for label, value in (
        ("render border", r.use_border),
        ("film transparent", r.film_transparent),
        ("stereo/multiview", r.use_multiview),
        ("metadata stamp", r.use_stamp),
        ("freestyle", r.use_freestyle),
        ("motion blur", r.use_motion_blur),
        ("simplify", r.use_simplify),
        ("adaptive sampling", c.use_adaptive_sampling),
        ("denoising", c.use_denoising),
        ("view curves", vs.use_curve_mapping),
        ("white balance", vs.use_white_balance),
    ):
        differs(label, value, False)
    differs("view transform", vs.view_transform, "Standard")
    differs("look", vs.look, "None")
    differs("exposure", round(vs.exposure, 3), 0.0)
    differs("gamma", round(vs.gamma, 3), 1.0)
    differs("dither", round(r.dither_intensity, 3), 0.0)
    differs("Cycles film exposure", round(c.film_exposure, 3), 1.0)
    differs("Cycles time limit", round(c.time_limit, 3), 0.0)
    if r.use_compositing and scene.compositing_node_group is not None:
        found.append(f"compositor: '{scene.compositing_node_group.name}' (visualenv: off)")
    if r.use_sequencer and scene.sequence_editor is not None and len(scene.sequence_editor.strips_all):
        found.append(f"sequencer: {len(scene.sequence_editor.strips_all)} strips (visualenv: off)")
    off = [layer.name for layer in scene.view_layers if not layer.use]
    if off:
        found.append(f"view layers switched off: {', '.join(off)} (visualenv renders the first one in use)")
    if scene.rigidbody_world is not None and scene.rigidbody_world.enabled:
        found.append("rigid body world (visualenv: not simulated)")
    return found


def describe(path: str) -> dict[str, Any]:
    turn_autorun_off()
    # use_scripts=False: no registered text runs
    bpy.ops.wm.open_mainfile(filepath=path, load_ui=False, use_scripts=False)
    scenes = []
    for scene in bpy.data.scenes:
        r = scene.render
        scenes.append(
            {
                "name": scene.name,
                "camera": scene.camera.name if scene.camera else None,
                "objects": [o.name for o in scene.objects],
                "engine": r.engine,
                "resolution": [r.resolution_x, r.resolution_y],
                "frame": scene.frame_current,
                "overrides": _overrides(scene),
            }
        )
    cameras, lights, meshes, empties, others = [], [], [], [], []
    for obj in bpy.data.objects:
        entry: dict[str, Any] = {
            "name": obj.name,
            "location": _vec(obj.location),
            "parent": obj.parent.name if obj.parent else None,
            "scenes": [s.name for s in obj.users_scene],
            "hide_render": obj.hide_render,
            "animated": _animated(obj),
        }
        if obj.type == "CAMERA":
            cam = obj.data
            entry.update(type=cam.type, lens=round(cam.lens, 3), ortho_scale=round(cam.ortho_scale, 3))
            cameras.append(entry)
        elif obj.type == "LIGHT":
            entry.update(type=obj.data.type, energy=round(obj.data.energy, 3))
            lights.append(entry)
        elif obj.type == "MESH":
            entry.update(
                dimensions=_vec(obj.dimensions),
                modifiers=[m.type for m in obj.modifiers],
                materials=[
                    {"name": s.material.name, "color_bindable": _bindable(s.material)}
                    for s in obj.material_slots
                    if s.material
                ],
            )
            meshes.append(entry)
        elif obj.type == "EMPTY":
            empties.append(entry)
        else:
            entry["type"] = obj.type
            others.append(entry)
    libraries = [
        {
            "path": lib.filepath,
            "found": os.path.exists(bpy.path.abspath(lib.filepath)),
            "uses": sorted(
                i.name
                for coll in (bpy.data.objects, bpy.data.meshes, bpy.data.materials)
                for i in coll
                if i.library == lib
            ),
        }
        for lib in bpy.data.libraries
    ]
    missing_images = [
        {"name": im.name, "path": im.filepath}
        for im in bpy.data.images
        if im.source in ("FILE", "SEQUENCE", "TILED")
        and im.packed_file is None
        and im.library is None
        and not os.path.exists(bpy.path.abspath(im.filepath))
    ]
    return {
        "file": path,
        "version": ".".join(str(v) for v in bpy.data.version),
        "scenes": scenes,
        "cameras": cameras,
        "lights": lights,
        "meshes": meshes,
        "empties": empties,
        "other_objects": others,
        "libraries": libraries,
        "missing_images": missing_images,
    }


def serve() -> None:
    """Answer describe requests from stdin until it closes."""
    answers = os.fdopen(os.dup(1), "w", encoding="utf-8")
    os.dup2(2, 1)  # Blender prints to stdout; the answers keep the original one
    while select.select([sys.stdin], [], [], IDLE_EXIT)[0]:
        line = sys.stdin.readline()
        if not line:
            return
        path = json.loads(line)["path"]
        try:
            answer: dict[str, Any] = {"ok": describe(path)}
        except Exception as exc:  # noqa: BLE001 - any failure to read is the answer
            answer = {"error": str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__}
        answers.write(json.dumps(answer) + "\n")
        answers.flush()


if __name__ == "__main__":
    serve()
