"""One table of bindable properties drives the spec model, the compiler, the renderer and the docs."""

from __future__ import annotations

import pytest
import re
from pathlib import Path

from visualenv.bindables import BINDABLES, camera_problem, type_problem
from visualenv.spec.models import Actor

DOCS = Path(__file__).resolve().parents[2] / "docs" / "spec.md"


def test_the_actor_model_has_one_field_per_bindable_property():
    assert list(Actor.model_fields) == list(BINDABLES)
    for name, field in Actor.model_fields.items():
        assert field.description == BINDABLES[name].description


def test_docs_name_every_bindable_property():
    section = DOCS.read_text(encoding="utf-8").split("## Actors (bindings)")[1].split("\n## ")[0]
    documented = set(re.findall(r"`([a-z_]+)`", section))
    assert set(BINDABLES) <= documented, f"docs/spec.md's Actors section misses {sorted(set(BINDABLES) - documented)}"


def test_type_and_camera_problems_name_what_was_expected():
    assert (
        type_problem("strength", "Box", "MESH") == "'strength' binds a light's power, but 'Box' is a mesh, not a light"
    )
    assert (
        type_problem("lens", "Lamp", "LIGHT")
        == "'lens' binds a camera's focal length, but 'Lamp' is a light, not a camera"
    )
    assert "'Cam' is a camera, not a mesh, a light or an empty" in type_problem("color", "Cam", "CAMERA")
    assert type_problem("color", "Rig", "EMPTY") is None and type_problem("location", "Cam", "CAMERA") is None
    assert camera_problem("Cam", {"Cam": "CAMERA"}) is None
    assert camera_problem("Box", {"Box": "MESH", "Cam": "CAMERA"}) == "'Box' is a mesh, not a camera (cameras: Cam)"
    missing = camera_problem("Camera", {"Box": "MESH", "Cam": "CAMERA"})
    assert "no camera 'Camera' in the scene (did you mean 'Cam'?" in missing and "objects: Box, Cam" in missing


@pytest.mark.blender
def test_the_blender_backend_has_a_setter_for_every_bindable_property():
    from visualenv.render.blender.binding_setters import SETTERS, SETTERS_WITH_STATE

    assert set(SETTERS) | set(SETTERS_WITH_STATE) == set(BINDABLES)
