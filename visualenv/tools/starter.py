"""`visualenv inspect` and `visualenv init`: what a .blend holds, in words, and a starter spec over it.

Both work from :func:`visualenv.render.blender.scene.blendfile.describe` (the file is read in a child process), so this
module needs no Blender itself.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

_YAML_WORDS = {"y", "n", "yes", "no", "true", "false", "on", "off", "null", "~"}


def yaml_name(name: str) -> str:
    """A Blender name as a YAML scalar: plain where YAML reads it back unchanged, quoted otherwise."""
    if re.fullmatch(r"[A-Za-z_.][A-Za-z0-9_./-]*", name) and name.lower() not in _YAML_WORDS:
        return name
    return '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _num(v: float) -> str:
    return f"{v:g}"


def _vec(v: list[float]) -> str:
    return "[" + ", ".join(_num(x) for x in v) + "]"


def _where(entry: dict[str, Any], several_scenes: bool) -> str:
    text = f"at {_vec(entry['location'])}"
    if entry["parent"]:
        text += f", parent {entry['parent']}"
    if several_scenes:
        text += f", in {', '.join(entry['scenes']) or 'no scene'}"
    if entry["hide_render"]:
        text += ", hidden in renders (bind `visible` to show it)"
    return text


def format_report(info: dict[str, Any]) -> str:
    """The text `visualenv inspect` prints."""
    several = len(info["scenes"]) > 1
    lines = [f"{info['file']} (saved by Blender {info['version']})"]
    for scene in info["scenes"]:
        lines.append(
            f"scene {yaml_name(scene['name'])}: camera {scene['camera'] or 'none'}, frame {scene['frame']}, "
            f"{scene['resolution'][0]}x{scene['resolution'][1]} asked (the spec's resolution is used), {len(scene['objects'])} objects"
        )
        for item in scene["overrides"]:
            lines.append(f"  overridden by visualenv: {item}")
    if several:
        lines.append("  several scenes: name one in the spec with scene.file_scene")
    sections = (
        (
            "cameras",
            lambda c: (
                f"{c['type'].lower()}, lens {_num(c['lens'])} mm"
                + (f", ortho scale {_num(c['ortho_scale'])}" if c["type"] == "ORTHO" else "")
            ),
        ),
        ("lights", lambda light: f"{light['type'].lower()}, {_num(light['energy'])} W"),
        (
            "meshes",
            lambda m: (
                f"{' x '.join(_num(d) for d in m['dimensions'])} m"
                + (f", modifiers {', '.join(m['modifiers'])}" if m["modifiers"] else "")
            ),
        ),
        ("empties", lambda e: "empty"),
        ("other_objects", lambda o: o["type"].lower()),
    )
    for key, describe in sections:
        if not info[key]:
            continue
        lines.append(key.replace("_", " ") + ":")
        for entry in info[key]:
            lines.append(f"  {yaml_name(entry['name'])}: {describe(entry)}, {_where(entry, several)}")
            for mat in entry.get("materials", []):
                lines.append(
                    f"    material {mat['name']}: "
                    + (
                        "takes a `color` binding"
                        if mat["color_bindable"]
                        else "no Principled BSDF, a `color` binding cannot reach it"
                    )
                )
            if entry["animated"]:
                lines.append(
                    f"    animated: {'; '.join(entry['animated'])} (a binding mutes what it binds; the rest stays animated)"
                )
    for lib in info["libraries"]:
        lines.append(f"linked library {lib['path']}: " + ("found" if lib["found"] else "NOT FOUND (an error at build)"))
    for image in info["missing_images"]:
        lines.append(f"image {image['name']}: file {image['path']} NOT FOUND (renders magenta; a warning at build)")
    return "\n".join(lines)


def _env_id(stem: str) -> str:
    words = re.findall(r"[A-Za-z0-9]+", stem)
    name = "".join(w[:1].upper() + w[1:] for w in words)
    if not name or not name[0].isalpha():
        name = "Scene" + name
    return f"{name}-v0"


def starter_spec(info: dict[str, Any], blend: Path, spec_path: Path) -> str:
    """A spec that validates and builds as it is: the file's scene, its first camera, placeholders to replace."""
    scenes = info["scenes"]
    scene = next((s for s in scenes if s["camera"]), scenes[0])
    in_scene = set(scene["objects"])
    cameras = [c["name"] for c in info["cameras"] if c["name"] in in_scene]
    camera = scene["camera"] or (cameras[0] if cameras else None)
    meshes = [m for m in info["meshes"] if m["name"] in in_scene]
    file = os.path.relpath(blend.resolve(), spec_path.resolve().parent).replace(os.sep, "/")
    out = [
        f"# A starter spec for {blend.name}, written by `visualenv init`: it builds as it is.",
        "# Replace the placeholder state, actions and dynamics, then bind objects under actors.",
        "# `visualenv inspect` lists what the file holds; docs/spec.md is the reference.",
        f"id: {_env_id(blend.stem)}",
        "",
        "scene:",
        f"  file: {yaml_name(file)}",
    ]
    if len(scenes) > 1:
        out.append(f"  file_scene: {yaml_name(scene['name'])}")
    if camera is None:
        camera = "Camera"
        out += [
            "  objects:  # the file has no camera: this one looks at the origin",
            "    Camera: {camera: perspective, lens: 35, location: [0, -10, 4], look_at: [0, 0, 0]}",
        ]
    out += [
        "",
        "state:",
        "  x: {init: 0.0}  # placeholder",
        "",
        "actions:",
        "  discrete: [{dx: -0.1}, {dx: 0.1}]  # placeholder",
        "",
        "dynamics:",
        "  update: {x: x + dx}  # placeholder",
        "",
        "actors: {}",
    ]
    if meshes:
        out.append("# Bind objects by removing the `{}` above and uncommenting lines like these:")
    for mesh in meshes:
        loc = mesh["location"]
        example = f"[{_num(loc[0]) + ' + x' if loc[0] else 'x'}, {_num(loc[1])}, {_num(loc[2])}]"
        colours = [m["name"] for m in mesh["materials"] if m["color_bindable"]]
        note = f"  {' x '.join(_num(d) for d in mesh['dimensions'])} m" + (
            f"; takes color (material {', '.join(colours)})" if colours else ""
        )
        out.append(f"#  {yaml_name(mesh['name'])}: {{location: {example}}}  #{note}")
    out += [
        "",
        f"observation: {{camera: {yaml_name(camera)}, resolution: [84, 84], color: rgb}}",
        "",
        "reward: 0.0  # placeholder",
        "max_steps: 100",
        "",
    ]
    return "\n".join(out)
