"""Numbers a batch's shaders read per env: :class:`EnvAttributes`.

Envs share their materials (instances of one mesh, linked duplicates). A number that differs from env to env is read
by an Attribute node of type Instancer, which an instance answers with its own attribute (written per env by
:meth:`~visualenv.render.blender.batch.instances.InstancedCopies.write_env_attributes`) and a copied object with its own
custom property (:class:`EnvAttributes`). Their names start with :data:`PREFIX`. A batch writes two kinds:

* each env's shift of a material's colour, a distraction (:mod:`batch_distractions`);
* how each env's camera is turned from the tiles camera's (a camera the state or a distraction turns): a MuJoCo
  look computes its headlight in camera space (:mod:`mujoco_look`), which in a batch is the tiles camera's, and
  :func:`turn_to_env_cameras` turns it on to env k's camera, as env k alone computes it.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

#: the names of the attributes a batch writes per env
PREFIX = "visualenv_env_"
#: each env's camera turn (an axis times its angle, in the tiles camera's Cycles camera space)
CAMERA_TURN = PREFIX + "camera_turn"


def shift_name(index: int) -> str:
    """The attribute that holds the colour shift of a scene's material `index` (in the order one env draws them)."""
    return f"{PREFIX}shift_{index}"


def env_attribute(nodes: Any, name: str) -> Any:
    """An Attribute node reading `name`: an instance's attribute, else its object's custom property."""
    node = nodes.new("ShaderNodeAttribute")
    node.attribute_type = "INSTANCER"
    node.attribute_name = name
    return node


def read_per_env(obj: Any) -> list[str]:
    """The per-env attributes the materials of `obj` read."""
    names = {
        node.attribute_name
        for slot in obj.material_slots
        if slot.material is not None and slot.material.node_tree
        for node in slot.material.node_tree.nodes
        if node.bl_idname == "ShaderNodeAttribute" and node.attribute_name.startswith(PREFIX)
    }
    return sorted(names)


def turn_to_env_cameras(scene: Any) -> bool:
    """Every material of `scene` turned on to each env's camera (:func:`turn_to_env_camera`); whether any turned."""
    materials = {
        slot.material
        for obj in scene.objects
        for slot in obj.material_slots
        if slot.material is not None and slot.material.node_tree is not None
    }
    return any([turn_to_env_camera(material) for material in materials])


def turn_to_env_camera(material: Any) -> bool:
    """Every vector the material turns into camera space turned on by the env's :data:`CAMERA_TURN` (the inverse of
    its rays' turn): the env's own camera space. Whether it has any."""
    nodes, links = material.node_tree.nodes, material.node_tree.links
    transforms = [n for n in nodes if n.bl_idname == "ShaderNodeVectorTransform" and n.convert_to == "CAMERA"]
    if not transforms:
        return False
    turn = env_attribute(nodes, CAMERA_TURN).outputs["Vector"]
    axis, angle = nodes.new("ShaderNodeVectorMath"), nodes.new("ShaderNodeVectorMath")
    axis.operation, angle.operation = "NORMALIZE", "LENGTH"
    links.new(turn, axis.inputs[0])
    links.new(turn, angle.inputs[0])
    for transform in transforms:
        rotate = nodes.new("ShaderNodeVectorRotate")
        rotate.rotation_type, rotate.invert = "AXIS_ANGLE", True
        links.new(axis.outputs["Vector"], rotate.inputs["Axis"])
        links.new(angle.outputs["Value"], rotate.inputs["Angle"])
        for link in list(transform.outputs["Vector"].links):
            links.new(rotate.outputs["Vector"], link.to_socket)
        links.new(transform.outputs["Vector"], rotate.inputs["Vector"])
    return True


class EnvAttributes:
    """Writes per-env attributes into a batch's instances and each env's copied objects that read them."""

    def __init__(self, objects: Sequence[Sequence[Any]], instances: Any) -> None:
        """`objects`: each env's own copied objects; `instances`: the :class:`InstancedCopies` (or None)."""
        self._objects = [[(obj, names) for obj in own if (names := read_per_env(obj))] for own in objects]
        self._instances = instances
        self._last: dict[str, np.ndarray] = {}

    @classmethod
    def of_copies(cls, copies: Sequence[Any], originals: Sequence[Any], instances: Any) -> EnvAttributes:
        """For a batch's copies (:class:`~visualenv.render.blender.batch.copies.Copy`; copy 0's objects are `originals`, those
        that are not instances; another's, those in its anchor's collection) and its instances."""
        return cls(
            [list(originals)]
            + [
                [o for o in copy.anchor.users_collection[0].objects if o != copy.anchor]
                if copy.anchor is not None
                else []
                for copy in copies[1:]
            ],
            instances,
        )

    def write(self, values: Mapping[str, np.ndarray]) -> None:
        """Each env's numbers, ``(N, 3)`` by attribute name; those that changed since the last write are written."""
        changed = {
            name: array
            for name, array in values.items()
            if name not in self._last or not np.array_equal(self._last[name], array)
        }
        if not changed:
            return
        if self._instances is not None:
            rgba = {name: np.ones((len(array), 4), dtype=np.float32) for name, array in changed.items()}
            for name, array in changed.items():
                rgba[name][:, :3] = array
            self._instances.write_env_attributes(rgba)
        for k, own in enumerate(self._objects):
            for obj, names in own:
                written = [
                    name
                    for name in names
                    if name in changed
                    and (name not in self._last or not np.array_equal(self._last[name][k], changed[name][k]))
                ]
                for name in written:
                    obj[name] = tuple(float(v) for v in changed[name][k])
                if written:
                    obj.update_tag()  # a custom property's change alone does not reach Cycles
        self._last.update({name: array.copy() for name, array in changed.items()})
