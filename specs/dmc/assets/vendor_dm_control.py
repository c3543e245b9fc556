"""Copy the MJCF files of the bundled DeepMind Control tasks from the installed dm_control into this folder, and check them.

    python specs/dmc/assets/vendor_dm_control.py

The DMC specs (specs/dmc/*.yaml) reproduce dm_control's tasks step for step, so they read these
files, pinned here, rather than whatever dm_control is installed (and a user needs no dm_control
to run them; only the parity tests import it). The suite's common assets (``common/materials.xml``,
``skybox.xml``, ``visual.xml``, which every task's XML includes) and the tasks' XML are copied byte
for byte, but for two edits (:data:`EDITS`), each checked to change nothing MuJoCo simulates:

* ``cheetah.xml``: its compiler's ``settotalmass="14"``, deprecated in MuJoCo 3 (a warning at
  every load), becomes the masses and inertias MuJoCo computes with it, written as each body's
  ``<inertial>`` (``inertiafromgeom="false"``), as Gymnasium's half_cheetah.xml is pinned
  (specs/mujoco/assets). The copy compiles to dm_control's model, MuJoCo's binary model equal.
* ``reacher.xml``: its camera ``hand`` is renamed ``hand_camera``: geoms, cameras and lights are
  the drawn scene's objects, named as in the model, and reacher has a geom ``hand`` too (one name
  for two objects is an error in visualenv). The copy compiles to the model dm_control's loader
  builds from its XML with that one rename, MuJoCo's binary model equal.

Every other copy compiles to the model dm_control's own loader builds (``get_model_and_assets()``),
MuJoCo's binary model equal. Quadruped's model is built at load: its tasks call ``make_model``, which
edits quadruped.xml (the floor's size, the walls, ball, terrain and rangefinders removed), so the
model each task loads is written as built (:data:`BUILT`, a comment added on top) and checked
against the model ``suite.load`` steps, MuJoCo's binary model equal. The script writes SOURCES.md (the dm_control version, each original's
sha256 and whether the copy is verbatim). dm_control is Apache-2.0 licensed: LICENSE.dm_control is
its licence, kept beside the copies.
"""

from __future__ import annotations

import hashlib
import importlib
import re
import sys
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np

HERE = Path(__file__).resolve().parent
#: the tasks' model files (suite/<name>), with the suite module whose get_model_and_assets() loads each
MODELS = {
    "cartpole.xml": "dm_control.suite.cartpole",
    "reacher.xml": "dm_control.suite.reacher",
    "cheetah.xml": "dm_control.suite.cheetah",
    "finger.xml": "dm_control.suite.finger",
    "ball_in_cup.xml": "dm_control.suite.ball_in_cup",
    "walker.xml": "dm_control.suite.walker",
    "pendulum.xml": "dm_control.suite.pendulum",
    "acrobot.xml": "dm_control.suite.acrobot",
    "hopper.xml": "dm_control.suite.hopper",
    "humanoid.xml": "dm_control.suite.humanoid",
}
#: models a task builds at load (quadruped's make_model), copied as built: file -> (suite module, task, the builder
#: called as the task calls it, the suite file it edits); the floor is the time limit (20 s) times the speed wide
BUILT: dict[str, tuple[str, str, Callable[[Any], bytes], str]] = {
    "quadruped_walk.xml": ("dm_control.suite.quadruped", "walk", lambda q: q.make_model(floor_size=10), "quadruped.xml"),
    "quadruped_run.xml": ("dm_control.suite.quadruped", "run", lambda q: q.make_model(floor_size=100), "quadruped.xml"),
}
COMMON = ("common/materials.xml", "common/skybox.xml", "common/visual.xml")
RENAMED_CAMERA = ('<camera name="hand" ', '<camera name="hand_camera" ')
CHEETAH_COMPILER = '<compiler settotalmass="14"/>'
CHEETAH_NOTE = ("<!-- visualenv: dm_control's settotalmass=\"14\" (deprecated in MuJoCo 3) is replaced by the inertials MuJoCo "
                "computed with it (specs/dmc/assets/vendor_dm_control.py): the compiled model is the same, bit for bit. -->")


def binary(model: Any) -> bytes:
    """MuJoCo's binary model file of `model` (MJB): every compiled array and setting."""
    import mujoco

    buffer = np.zeros(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return buffer.tobytes()


def compile_quietly(xml: str, assets: dict[str, bytes]) -> Any:
    """The MjModel of `xml` with `assets`, the known settotalmass deprecation warning of the original silenced (only here)."""
    from visualenv.physics.model import mujoco_module

    mujoco = mujoco_module()  # MuJoCo's warnings as Python warnings
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="MuJoCo: compiler attribute 'settotalmass' is deprecated")
        return mujoco.MjModel.from_xml_string(xml, assets)


def with_inertials(source: str, assets: dict[str, bytes]) -> str:
    """dm_control's cheetah.xml with settotalmass replaced by the inertial of every body, as MuJoCo computes them."""
    from visualenv.physics.model import mujoco_module

    mujoco, model = mujoco_module(), compile_quietly(source, assets)

    def number(v: Any) -> str:
        return repr(float(v))

    text = source.replace(CHEETAH_COMPILER, '<compiler inertiafromgeom="false"/>\n  ' + CHEETAH_NOTE)
    if text == source:
        raise SystemExit("cheetah.xml: its compiler line is not the one this script edits; check the new dm_control's file by hand")
    for b in range(1, model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b)
        tag = re.search(rf'( *)<body name="{re.escape(name)}"[^>]*>\n', text)
        if tag is None:
            raise SystemExit(f"cheetah.xml: no <body name=\"{name}\"> line")
        inertial = (f'{tag.group(1)}  <inertial pos="{" ".join(map(number, model.body_ipos[b]))}" '
                    f'quat="{" ".join(map(number, model.body_iquat[b]))}" mass="{number(model.body_mass[b])}" '
                    f'diaginertia="{" ".join(map(number, model.body_inertia[b]))}"/>\n')
        text = text[:tag.end()] + inertial + text[tag.end():]
    return text


def renamed_camera(source: str, assets: dict[str, bytes]) -> str:
    """dm_control's reacher.xml with its camera 'hand' (a geom's name too) renamed 'hand_camera'."""
    old, new = RENAMED_CAMERA
    if source.count(old) != 1:
        raise SystemExit("reacher.xml: no single camera 'hand' to rename; check the new dm_control's file by hand")
    return source.replace(old, new)


#: the copies that are not verbatim: how each is edited, and what the check compares it with (dm_control's XML, edited so)
EDITS: dict[str, tuple[Callable[[str, dict[str, bytes]], str], Callable[[str, dict[str, bytes]], str], str]] = {
    "cheetah.xml": (with_inertials, lambda xml, assets: xml, "edited (settotalmass written out as inertials)"),
    "reacher.xml": (renamed_camera, renamed_camera, "edited (camera 'hand' renamed 'hand_camera')"),
}


def expected_model(name: str, module: str) -> Any:
    """The model the copy of `name` must compile to: dm_control's loader's, from its XML with the rename of EDITS, if any."""
    xml, assets = importlib.import_module(module).get_model_and_assets()
    text = xml.decode("utf-8") if isinstance(xml, bytes) else xml
    if name in EDITS:
        text = EDITS[name][1](text, assets)
    return compile_quietly(text, assets)


def check(name: str, module: str, folder: Path = HERE) -> None:
    """SystemExit unless the copy in `folder` compiles to the model dm_control builds (MJB equal), with the rename of EDITS."""
    _, assets = importlib.import_module(module).get_model_and_assets()
    ours = compile_quietly((folder / name).read_text(encoding="utf-8"), assets)
    if binary(ours) != binary(expected_model(name, module)):
        raise SystemExit(f"{name}: the copy compiles to another model than dm_control's loader builds")


def build(name: str) -> str:
    """The model `name` of :data:`BUILT`, as its task builds it, with a comment saying so."""
    module, task, builder, source = BUILT[name]
    xml = builder(importlib.import_module(module)).decode("utf-8")
    note = (f"<!-- visualenv: dm_control's {source} as {module}.{task} builds it at load (make_model), written out by "
            "specs/dmc/assets/vendor_dm_control.py: it compiles to the model suite.load steps, bit for bit. -->\n")
    return note + xml


def check_built(name: str, folder: Path = HERE) -> None:
    """SystemExit unless the copy of a :data:`BUILT` model compiles to the model ``suite.load`` steps (MJB equal)."""
    from dm_control import suite

    module, task, _, _ = BUILT[name]
    domain = module.rsplit(".", 1)[1]
    assets = importlib.import_module("dm_control.suite.common").ASSETS  # the task's Physics.from_xml_string reads these
    ours = compile_quietly((folder / name).read_text(encoding="utf-8"), assets)
    if binary(ours) != binary(suite.load(domain, task).physics.model.ptr):
        raise SystemExit(f"{name}: the copy compiles to another model than suite.load({domain!r}, {task!r}) steps")


def main() -> None:
    from importlib import metadata

    from visualenv.files import package_file

    suite = package_file("package:dm_control.suite/cartpole.xml").parent
    version = metadata.version("dm_control")
    rows = []
    for name in (*MODELS, *COMMON):
        original = (suite / name).read_bytes()
        (HERE / name).parent.mkdir(exist_ok=True)
        if name in EDITS:
            _, assets = importlib.import_module(MODELS[name]).get_model_and_assets()
            (HERE / name).write_text(EDITS[name][0](original.decode("utf-8"), assets), encoding="utf-8")
        else:
            (HERE / name).write_bytes(original)
        rows.append(f"| `{name}` | `{hashlib.sha256(original).hexdigest()}` | {EDITS[name][2] if name in EDITS else 'verbatim'} |")
    for name, (_, task, _, source) in BUILT.items():
        (HERE / name).write_text(build(name), encoding="utf-8")
        digest = hashlib.sha256((suite / source).read_bytes()).hexdigest()
        rows.append(f"| `{name}` | `{digest}` (`{source}`) | built as `{task}()` builds it (make_model) |")
    for name, module in MODELS.items():
        check(name, module)
    for name in BUILT:
        check_built(name)
    (HERE / "SOURCES.md").write_text(f"""\
# Where these files come from

dm_control {version} (https://github.com/google-deepmind/dm_control, Apache License 2.0: `LICENSE.dm_control`,
Copyright 2017 The dm_control Authors), `dm_control/suite/`, copied by `vendor_dm_control.py`, which checks that each
task's copy compiles to the model dm_control's own loader builds (MuJoCo's binary model, equal; its docstring says
what the two edited copies change and what they are compared with).

| file | sha256 of dm_control's file | here |
| --- | --- | --- |
{chr(10).join(rows)}
""", encoding="utf-8")
    print(f"wrote {', '.join((*MODELS, *BUILT, *COMMON))} and SOURCES.md from dm_control {version}", file=sys.stderr)


if __name__ == "__main__":
    main()
