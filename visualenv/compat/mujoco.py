"""MuJoCo's model fields and Python API that changed across the versions visualenv supports (``mujoco>=3.2,<4``).

Each gate tests for the field or call itself, so that every supported MuJoCo takes its own route:

* :func:`light_directional`: MuJoCo 3.3.3 replaced the boolean ``light_directional`` with the enum ``light_type``
  (3.2.0 to 3.3.2 have only the boolean);
* :func:`texture_channels`: ``tex_nchannel`` came with MuJoCo 3.2.1 (1, 3 or 4 channels); 3.2.0's textures are RGB;
* :func:`ctrl_limited`: ``actuator_ctrllimited`` is in every supported MuJoCo (the compiler resolves ``autolimits``
  into it); the gate keeps the ctrlrange in force should a release drop it;
* :func:`spec_deletes`: ``MjSpec.delete(element)`` came with MuJoCo 3.3.4 (before it, ``element.delete()``); the
  model without textures (:func:`visualenv.physics.model.without_textures`) is compiled only where it is there;
* :func:`batch_api`: ``mujoco.batch``, which steps many simulations in one call, came with MuJoCo 3.17.

The fields' history was read in MuJoCo's headers and Python bindings at each release tag from 3.2.0 to 3.12.0, and
every gate runs on the installed 3.17. ``tests/compat/test_mujoco.py`` fails when MuJoCo moves: another version (read
its changelog for these fields, then add it to :data:`CHECKED`), or a field or call gone.
"""

from __future__ import annotations

import importlib
from typing import Any

from visualenv.versions import mujoco_version

#: the MuJoCo versions (major.minor) whose fields and calls were checked for what the gates rely on
CHECKED = ("3.2", "3.3", "3.4", "3.5", "3.6", "3.7", "3.8", "3.9", "3.10", "3.11", "3.12", "3.17")
#: ``mjtLightType.mjLIGHT_DIRECTIONAL``, the value of ``light_type`` for a directional light
LIGHT_DIRECTIONAL = 1


def checked() -> bool:
    """Whether the installed MuJoCo is one this module was checked against."""
    installed = mujoco_version()
    return installed is not None and ".".join(installed.split(".")[:2]) in CHECKED


def light_directional(model: Any, light: int) -> bool:
    """Whether `light` of the MjModel is directional: ``light_type`` (MuJoCo 3.3.3 on), else ``light_directional``."""
    if hasattr(model, "light_type"):
        return int(model.light_type[light]) == LIGHT_DIRECTIONAL
    return bool(model.light_directional[light])


def texture_channels(model: Any, texture: int) -> int:
    """The channels of `texture` of the MjModel: ``tex_nchannel`` (MuJoCo 3.2.1 on), else 3 (RGB, all 3.2.0 had)."""
    return int(model.tex_nchannel[texture]) if hasattr(model, "tex_nchannel") else 3


def ctrl_limited(model: Any, actuator: int) -> bool:
    """Whether `actuator` of the MjModel clamps its control to its ctrlrange (``actuator_ctrllimited``); limited where
    the field is missing, so that the range stays in force."""
    return bool(model.actuator_ctrllimited[actuator]) if hasattr(model, "actuator_ctrllimited") else True


def spec_deletes(mujoco: Any) -> bool:
    """Whether this MuJoCo's ``MjSpec`` deletes elements (``spec.delete(element)``, MuJoCo 3.3.4 on)."""
    return hasattr(getattr(mujoco, "MjSpec", None), "delete")


def batch_api() -> Any | None:
    """The ``mujoco.batch`` module (MuJoCo 3.17 on); None where the installed MuJoCo has none, or no MuJoCo is there."""
    try:
        return importlib.import_module("mujoco.batch")
    except ImportError:
        return None
