"""`visualenv inspect model.xml` and `visualenv init model.xml`: an MJCF model's names, and a starter spec over it.

The names are those expressions read (:mod:`visualenv.physics.model`); the
starter spec drives every actuator (the default actions), observes through the
model's first camera (or, in a model without one, a camera of its own that frames
the model), lists the names as comments and has a placeholder reward, so it
builds and steps as written.
"""

from __future__ import annotations

import math
import os
import re
import textwrap
from pathlib import Path

import numpy as np

from visualenv.physics.model import PhysicsModel, load_model, mujoco_module
from visualenv.physics.scene import visible_sites

#: what `init` and `inspect` take for an MJCF file (anything else is a .blend)
MJCF_SUFFIXES = (".xml", ".mjcf")
#: horizontal field of view of the starter camera's 35 mm lens on a 36 mm sensor
_HALF_FOV = math.atan(18 / 35)
#: names YAML reads as something else than a string unquoted (a camera called `on` would be `true`)
_YAML_WORDS = {"null", "true", "false", "yes", "no", "on", "off", "y", "n"}


def is_mjcf(path: Path) -> bool:
    return path.suffix.lower() in MJCF_SUFFIXES


def mjcf_report(path: Path) -> str:
    """The text `visualenv inspect model.xml` prints: the model's sizes and every name an expression can read."""
    physics = load_model(path)
    m = physics.model
    idents = physics.names.ident
    lines = [
        f"{path} (MJCF): timestep {m.opt.timestep:g} s, {m.nbody - 1} bodies, {m.njnt} joints, {m.nu} actuators, "
        f"{m.ngeom} geoms, {m.ncam} cameras, {m.nlight} lights, {m.nkey} keyframes"
    ]
    for i, name in enumerate(idents["actuator"]):
        lo, hi = physics.ctrl_range(i)
        lines.append(f"  actuator {name}: ctrl_{name} in [{lo:g}, {hi:g}]")
    for title, names in physics.listing().items():
        lines.append(f"{title}: " + ", ".join(names))
    kinds = {
        0: "plane",
        1: "hfield",
        2: "sphere",
        3: "capsule",
        4: "ellipsoid",
        5: "cylinder",
        6: "box",
        7: "mesh",
        8: "sdf",
    }
    drawn = [
        f"{idents['geom'][g]} ({kinds.get(int(m.geom_type[g]), '?')})"
        for g in range(m.ngeom)
        if int(m.geom_group[g]) < 3
    ]
    hidden = [idents["geom"][g] for g in range(m.ngeom) if int(m.geom_group[g]) >= 3]
    lines.append(
        "drawn geoms: "
        + (", ".join(drawn) or "none")
        + (f"; hidden (group >= 3): {', '.join(hidden)}" if hidden else "")
    )
    if m.nsite:
        sites = [f"{s.name[5:]} ({s.kind})" for s in visible_sites(physics)]
        lines.append(
            "drawn sites (physics.draw_sites): " + (", ".join(sites) or "none") + " (groups 0 to 2, not transparent)"
        )
    if "hfield" in " ".join(drawn) or "sdf" in " ".join(drawn):
        lines.append(
            "  a height field or SDF cannot be drawn yet: a rendered spec over this model is refused (hide it in group 3)"
        )
    lines.append("cameras (observation.camera): " + (", ".join(idents["camera"]) or "none: the spec adds its own"))
    head = m.vis.headlight
    lines.append(
        "lights: "
        + (", ".join(idents["light"]) or "none")
        + "; MuJoCo's headlight: "
        + (f"ambient {head.ambient[0]:g}, diffuse {head.diffuse[0]:g}" if head.active else "off")
    )
    return "\n".join(lines)


def _env_id(stem: str) -> str:
    words = re.findall(r"[A-Za-z0-9]+", stem)
    name = "".join(w[:1].upper() + w[1:] for w in words)
    return f"{name if name[:1].isalpha() else 'Model' + name}-v0"


def framing(physics: PhysicsModel) -> tuple[list[float], list[float]]:
    """A camera location and a point to look at that show every geom but the planes, at qpos0."""
    mujoco = mujoco_module()
    model = physics.model
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    solid = [g for g in range(model.ngeom) if int(model.geom_type[g]) != 0 and int(model.geom_group[g]) < 3]
    if not solid:
        return [0.0, -5.0, 2.0], [0.0, 0.0, 0.0]
    centres = data.geom_xpos[solid]
    radii = model.geom_rbound[solid]
    low, high = (centres - radii[:, None]).min(axis=0), (centres + radii[:, None]).max(axis=0)
    centre = (low + high) / 2
    radius = max(float(np.linalg.norm(high - low)) / 2, 0.05)
    distance = 1.2 * radius / math.tan(_HALF_FOV)
    eye = centre + np.array([0.0, -distance, 0.35 * distance])
    return [round(float(v), 3) for v in eye], [round(float(v), 3) for v in centre]


def _observation(physics: PhysicsModel) -> list[str]:
    """The starter's observation: through the model's first camera where it has one, else a camera of the spec's own framing it."""
    cameras = [f"'{c}'" if c.lower() in _YAML_WORDS else c for c in physics.names.ident["camera"]]
    if cameras:
        others = f"; its others: {', '.join(cameras[1:])}" if len(cameras) > 1 else ""
        return [
            f"# the model's first camera, {cameras[0]} (observation.camera takes any of the model's cameras by name{others})",
            f"observation: {{camera: {cameras[0]}, resolution: [84, 84], color: rgb}}",
        ]
    eye, target = framing(physics)
    return [
        "scene:",
        "  objects:  # the model has no camera: one that frames the model at its reset pose",
        f"    Camera: {{camera: perspective, lens: 35, location: {eye}, look_at: {target}}}",
        "observation: {camera: Camera, resolution: [84, 84], color: rgb}",
    ]


def mjcf_starter_spec(path: Path, spec_path: Path) -> str:
    """A spec over the MJCF at `path` that builds and steps as written."""
    physics = load_model(path)
    model_ref = os.path.relpath(path.resolve(), spec_path.resolve().parent).replace(os.sep, "/")
    actuators = [f"ctrl_{a}" for a in physics.actuator_names()]
    out = [
        f"# A starter spec for {path.name}, written by `visualenv init`: it builds and steps as it is.",
        "# Replace the placeholder reward, add outcomes and reset noise; docs/physics.md is the reference.",
        f"id: {_env_id(path.stem)}",
        "",
        "physics:",
        "  engine: mujoco",
        f"  model: {model_ref}",
        f"  frame_skip: 1   # the model's timestep is {physics.timestep:g} s: dt = timestep * frame_skip",
        "  # reset:",
        "  #   values: {qpos_<joint>: qpos_<joint> + uniform(-0.1, 0.1)}",
        "",
        "# Names expressions can read:",
    ]
    for title, names in physics.listing().items():
        shown = ", ".join(names[:60]) + (", ..." if len(names) > 60 else "")
        out += textwrap.wrap(
            f"{title}: {shown}", width=118, initial_indent="#   ", subsequent_indent="#       ", break_on_hyphens=False
        )
    out.append("")
    if actuators:
        out.append(
            f"# actions: not declared, so one Box dimension per actuator in its ctrlrange: {', '.join(actuators)}"
        )
    else:
        out += ["actions:  # the model has no actuators: one action that does nothing", "  discrete: [{}]"]
    out += [
        "",
        *_observation(physics),
        "",
        "reward: 0.0  # placeholder, e.g. a body's height: body_<name>_z",
        "max_steps: 1000",
        "",
    ]
    return "\n".join(out)
