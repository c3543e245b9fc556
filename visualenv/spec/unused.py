"""Fields that are valid on their own but do nothing where they are written.

A ``radius`` on a cube or a ``spot_size`` on a sun light is accepted by the
models (the fields exist on the class) yet changes nothing: most likely a
typo for another kind or a leftover. Each is reported at its key.
"""

from __future__ import annotations

from visualenv.spec.models import CameraObject, LightObject, PrimitiveObject, Spec

#: the shape fields each primitive kind uses (every other shape field is ignored)
PRIMITIVE_FIELDS = {
    "cube": {"size"},
    "plane": {"size"},
    "sphere": {"radius", "segments"},
    "disk": {"radius", "segments"},
    "cylinder": {"radius", "depth", "segments"},
    "cone": {"radius", "depth", "segments"},
    "torus": {"radius", "thickness", "segments"},
    "ring": {"radius", "thickness", "segments"},
    "terrain": {"size", "segments", "craters", "heightmap"},
}
_SHAPE_FIELDS = {"size", "radius", "depth", "thickness", "segments", "craters", "heightmap"}


def unused_fields(spec: Spec) -> list[tuple[tuple, str]]:
    """(path, message) for every field that has no effect on its object."""
    out: list[tuple[tuple, str]] = []
    for name, obj in spec.scene.objects.items():
        path = ("scene", "objects", name)
        if isinstance(obj, PrimitiveObject):
            used = PRIMITIVE_FIELDS[obj.primitive]
            for field in sorted(obj.model_fields_set & (_SHAPE_FIELDS - used), key=list(type(obj).model_fields).index):
                out.append((path + (field,), f"'{field}' does nothing on a {obj.primitive} (it uses {_words(used)})"))
        elif isinstance(obj, LightObject) and obj.light != "spot" and "spot_size" in obj.model_fields_set:
            out.append(
                (
                    path + ("spot_size",),
                    f"'spot_size' does nothing on a {obj.light} light (only spot lights have a cone)",
                )
            )
        elif isinstance(obj, CameraObject):
            wrong = "ortho_scale" if obj.camera == "perspective" else "lens"
            if wrong in obj.model_fields_set:
                right = "lens" if wrong == "ortho_scale" else "ortho_scale"
                out.append((path + (wrong,), f"'{wrong}' does nothing on a {obj.camera} camera (it uses '{right}')"))
    return out


def _words(fields: set[str]) -> str:
    names = [f"'{f}'" for f in sorted(fields)]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
