"""Copy the MJCF files of the bundled DeepMind Control tasks from the installed dm_control into this folder, and check them.

    python specs/dmc/assets/vendor_dm_control.py

The DMC specs (specs/dmc/*.yaml) reproduce dm_control's tasks step for step, so they read these
files, pinned here, rather than whatever dm_control is installed (and a user needs no dm_control
to run them; only the parity tests import it). Each task's XML and the suite's common assets
(``common/materials.xml``, ``skybox.xml``, ``visual.xml``, which the XML includes) are copied byte
for byte. The script checks that each copy compiles to the model dm_control's own loader builds
(``get_model_and_assets()``), equal as MuJoCo's binary model file, and writes SOURCES.md (the
dm_control version and each file's sha256). dm_control is Apache-2.0 licensed: LICENSE.dm_control
is its licence, kept beside the copies, which are unmodified.
"""

from __future__ import annotations

import hashlib
import importlib
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
#: the tasks' model files (suite/<name>), with the suite module whose get_model_and_assets() loads each
MODELS = {"cartpole.xml": "dm_control.suite.cartpole"}
COMMON = ("common/materials.xml", "common/skybox.xml", "common/visual.xml")


def binary(model: Any) -> bytes:
    """MuJoCo's binary model file of `model` (MJB): every compiled array and setting."""
    import mujoco

    buffer = np.zeros(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return buffer.tobytes()


def main() -> None:
    import mujoco
    from importlib import metadata

    from visualenv.files import package_file

    suite = package_file("package:dm_control.suite/cartpole.xml").parent
    version = metadata.version("dm_control")
    rows = []
    for name in (*MODELS, *COMMON):
        original = (suite / name).read_bytes()
        (HERE / name).parent.mkdir(exist_ok=True)
        shutil.copyfile(suite / name, HERE / name)
        rows.append(f"| `{name}` | `{hashlib.sha256(original).hexdigest()}` |")
    for name, module in MODELS.items():
        xml, assets = importlib.import_module(module).get_model_and_assets()
        if binary(mujoco.MjModel.from_xml_path(str(HERE / name))) != binary(mujoco.MjModel.from_xml_string(xml, assets)):
            raise SystemExit(f"{name}: the copy compiles to another model than dm_control's loader builds")
    (HERE / "SOURCES.md").write_text(f"""\
# Where these files come from

dm_control {version} (https://github.com/google-deepmind/dm_control, Apache License 2.0: `LICENSE.dm_control`,
Copyright 2017 The dm_control Authors), `dm_control/suite/`, copied unmodified by `vendor_dm_control.py`, which
checks that each task's copy compiles to the model dm_control's own loader builds (MuJoCo's binary model, equal).

| file | sha256 (dm_control's file and the copy) |
| --- | --- |
{chr(10).join(rows)}
""", encoding="utf-8")
    print(f"wrote {', '.join((*MODELS, *COMMON))} and SOURCES.md from dm_control {version}", file=sys.stderr)


if __name__ == "__main__":
    main()
