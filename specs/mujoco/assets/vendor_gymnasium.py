"""Copy the MJCF files the bundled MuJoCo ports read from the installed Gymnasium into this folder, and check them.

    python specs/mujoco/assets/vendor_gymnasium.py

The ports (specs/mujoco/*.yaml) reproduce Gymnasium's envs step for step, so they read these files,
pinned here, rather than whatever Gymnasium is installed. inverted_pendulum.xml and reacher.xml are
copied byte for byte. half_cheetah.xml is Gymnasium's but for one edit: its compiler's
``settotalmass="14"``, deprecated in MuJoCo 3 (a warning at every load), becomes the masses and
inertias MuJoCo computes with it, written as each body's ``<inertial>`` (``inertiafromgeom="false"``:
the geoms no longer add any). The script checks that the edited file compiles to the same model as
Gymnasium's, every array and statistic bit for bit, and writes SOURCES.md (the Gymnasium version and
each original's sha256). Gymnasium is MIT-licensed: LICENSE.gymnasium is its licence, kept beside
the copies.
"""

from __future__ import annotations

import hashlib
import re
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
VERBATIM = ("inverted_pendulum.xml", "reacher.xml")
EDITED = "half_cheetah.xml"
EDIT_NOTE = ("<!-- visualenv: Gymnasium's settotalmass=\"14\" (deprecated in MuJoCo 3) is replaced by the inertials MuJoCo "
             "computed with it (specs/mujoco/assets/vendor_gymnasium.py): the compiled model is the same, bit for bit. -->")


def gymnasium_assets() -> tuple[Path, str]:
    """Gymnasium's MuJoCo asset folder and Gymnasium's version, read from disk (Gymnasium is not imported)."""
    from importlib import metadata

    from visualenv.files import package_file

    return package_file("package:gymnasium.envs.mujoco/assets/reacher.xml").parent, metadata.version("gymnasium")


def compile_quietly(xml: str) -> Any:
    """The MjModel of `xml`, the known settotalmass deprecation warning of the original silenced (only here)."""
    from visualenv.physics.model import mujoco_module

    mujoco = mujoco_module()  # MuJoCo's warnings as Python warnings
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="MuJoCo: compiler attribute 'settotalmass' is deprecated")
        return mujoco.MjModel.from_xml_string(xml)


def differences(a: Any, b: Any, prefix: str = "") -> list[str]:
    """The fields of two MjModels (arrays, numbers, and the opt/stat/vis structs, vis's parts too) that differ by even one bit."""
    out = []
    for name in dir(a):
        value: Any = getattr(a, name, None)
        other: Any = getattr(b, name, None)
        if name.startswith("_") or callable(value):
            continue
        if isinstance(value, np.ndarray):
            if value.shape != other.shape or value.tobytes() != other.tobytes():
                out.append(prefix + name)
        elif isinstance(value, (int, float, str)):
            if value != other:
                out.append(prefix + name)
        elif (not prefix and name in ("opt", "stat", "vis")) or prefix == "vis.":
            out += differences(value, other, f"{prefix}{name}.")
    return out


def with_inertials(source: str) -> str:
    """Gymnasium's half_cheetah.xml with settotalmass replaced by the inertial of every body, as MuJoCo computes them."""
    from visualenv.physics.model import mujoco_module

    mujoco, model = mujoco_module(), compile_quietly(source)

    def number(v: Any) -> str:
        return repr(float(v))

    text = source.replace(' inertiafromgeom="true" settotalmass="14"/>', ' inertiafromgeom="false"/>\n  ' + EDIT_NOTE)
    if text == source:
        raise SystemExit("half_cheetah.xml: its compiler line is not the one this script edits; check the new Gymnasium's file by hand")
    for b in range(1, model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b)
        tag = re.search(rf'( *)<body name="{re.escape(name)}"[^>]*>\n', text)
        if tag is None:
            raise SystemExit(f"half_cheetah.xml: no <body name=\"{name}\"> line")
        inertial = (f'{tag.group(1)}  <inertial pos="{" ".join(map(number, model.body_ipos[b]))}" '
                    f'quat="{" ".join(map(number, model.body_iquat[b]))}" mass="{number(model.body_mass[b])}" '
                    f'diaginertia="{" ".join(map(number, model.body_inertia[b]))}"/>\n')
        text = text[:tag.end()] + inertial + text[tag.end():]
    return text


def main() -> None:
    assets, version = gymnasium_assets()
    sources = []
    for name in (*VERBATIM, EDITED):
        original = (assets / name).read_bytes()
        sources.append(f"| `{name}` | `{hashlib.sha256(original).hexdigest()}` | {'edited (settotalmass)' if name == EDITED else 'verbatim'} |")
        text = with_inertials(original.decode("utf-8")) if name == EDITED else original.decode("utf-8")
        changed = differences(compile_quietly(original.decode("utf-8")), compile_quietly(text)) if name == EDITED else []
        if changed:
            raise SystemExit(f"{name}: the edited model differs from Gymnasium's in {', '.join(changed)}")
        (HERE / name).write_text(text, encoding="utf-8")
    (HERE / "SOURCES.md").write_text(f"""\
# Where these files come from

Gymnasium {version} (https://github.com/Farama-Foundation/Gymnasium, MIT licence: `LICENSE.gymnasium`),
`gymnasium/envs/mujoco/assets/`, copied by `vendor_gymnasium.py` (its docstring says what it edits and checks).

| file | sha256 of Gymnasium's file | here |
| --- | --- | --- |
{chr(10).join(sources)}
""", encoding="utf-8")
    print(f"wrote {', '.join((*VERBATIM, EDITED))} and SOURCES.md from Gymnasium {version}", file=sys.stderr)


if __name__ == "__main__":
    main()
