"""The Geometry Nodes groups a batch's instances are drawn with, and the meshes realized or joined once.

:class:`~visualenv.render.blender.batch.instances.InstancedCopies` decides what is instanced; this module builds the node
groups (an instancer: points -> Instance on Points -> Set Instance Transform; a static group: members joined and
realized), tells whether a static mesh may be realized with the same pixels (:func:`realizable`: its materials must
not read its placement, :func:`reads_placement`), and lets a material read each instance's bound colour.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import bpy
import numpy as np

from visualenv.render.blender.look.materials import color_sockets

#: attribute names on the instancers' points (and so on their instances)
TRANSFORM, VISIBLE, COLOR = "visualenv_transform", "visualenv_visible", "visualenv_color"


#: the most triangles a static mesh's realized copies (every env's, in one mesh) may hold; past it they stay instances
REALIZED_TRIANGLES = 250_000


#: what Cycles reads from an instance's own object, given to the object that holds the realized mesh
RAY_SETTINGS = (
    "visible_camera",
    "visible_diffuse",
    "visible_glossy",
    "visible_transmission",
    "visible_volume_scatter",
    "visible_shadow",
    "is_shadow_catcher",
    "is_holdout",
    "pass_index",
    "color",
    "lightgroup",
    "shadow_terminator_shading_offset",
    "shadow_terminator_geometry_offset",
)


CYCLES_SETTINGS = ("is_caustics_caster", "is_caustics_receiver", "ao_distance")


#: shader nodes that read the object itself (its place, index, instancer or particles): a realized mesh would differ
PLACEMENT_NODES = frozenset(
    {
        "ShaderNodeObjectInfo",
        "ShaderNodeParticleInfo",
        "ShaderNodeHairInfo",
        "ShaderNodePointInfo",
        "ShaderNodeScript",
        "ShaderNodeDisplacement",
        "ShaderNodeVectorDisplacement",
        "ShaderNodeTexPointDensity",
    }
)


#: textures whose unlinked vector is the generated coordinates (an Image texture's is the UV map: the same once realized)
GENERATED_BY_DEFAULT = frozenset(
    {
        "ShaderNodeTexBrick",
        "ShaderNodeTexChecker",
        "ShaderNodeTexGabor",
        "ShaderNodeTexGradient",
        "ShaderNodeTexMagic",
        "ShaderNodeTexNoise",
        "ShaderNodeTexVoronoi",
        "ShaderNodeTexWave",
        "ShaderNodeTexWhiteNoise",
        "ShaderNodeTexEnvironment",
    }
)


def static_groups(meshes: Sequence[Any]) -> dict[tuple, list[Any]]:
    """Static meshes in groups that one mesh may draw: those whose object settings Cycles reads (ray visibility, pass
    index, ...) are the same; only groups of two or more (one alone gains nothing)."""
    groups: dict[tuple, list[Any]] = {}
    for obj in meshes:
        key = tuple(_setting(getattr(obj, s)) for s in RAY_SETTINGS) + tuple(
            _setting(getattr(obj.cycles, s)) for s in CYCLES_SETTINGS
        )
        groups.setdefault(key, []).append(obj)
    return {key: members for key, members in groups.items() if len(members) > 1}


def _setting(value: Any) -> Any:
    return tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value


def joined_mesh_group(name: str, members: Sequence[Any]) -> Any:
    """A node group that outputs `members` joined into one realized mesh, in the modified object's space."""
    group = geometry_node_group(name)
    nodes, links = group.nodes, group.links
    join = nodes.new("GeometryNodeJoinGeometry")
    for obj in members:
        info = nodes.new("GeometryNodeObjectInfo")
        info.transform_space = "RELATIVE"  # in the holder's space: the anchor's
        info.inputs["Object"].default_value = obj
        links.new(info.outputs["Geometry"], join.inputs[0])
    realize = nodes.new("GeometryNodeRealizeInstances")
    links.new(join.outputs[0], realize.inputs["Geometry"])
    links.new(realize.outputs["Geometry"], nodes.new("NodeGroupOutput").inputs[0])
    return group


def realizable(obj: Any, num_envs: int) -> bool:
    """Whether every env's copy of this static mesh may be one realized mesh, with the same pixels as its instances:
    its materials do not read its placement, no object-level material, light linking or modifier sets it apart, and
    the copies' triangles stay under :data:`REALIZED_TRIANGLES`."""
    if obj.light_linking.receiver_collection is not None or obj.light_linking.blocker_collection is not None:
        return False
    if any(slot.link == "OBJECT" for slot in obj.material_slots):  # an object's own materials are not realized with it
        return False
    if any(slot.material is not None and reads_placement(slot.material.node_tree) for slot in obj.material_slots):
        return False
    if obj.modifiers:  # their triangles are not known before evaluation (a subdivision's can be many): kept instanced
        return False
    return num_envs * _triangles(obj.data) <= REALIZED_TRIANGLES


def _triangles(mesh: Any) -> int:
    totals = np.empty(len(mesh.polygons), dtype=np.int64)
    mesh.polygons.foreach_get("loop_total", totals)
    return int((totals - 2).sum())


#: per shader node kind, whether such a node reads its object's placement (see :func:`reads_placement`)
_PLACEMENT_READERS: dict[str, Callable[[Any], bool]] = {
    "ShaderNodeTexCoord": lambda n: (
        n.from_instancer or any(n.outputs[o].is_linked for o in ("Generated", "Object", "Normal"))
    ),
    "ShaderNodeAttribute": lambda n: n.attribute_type in ("OBJECT", "INSTANCER"),
    "ShaderNodeUVMap": lambda n: n.from_instancer,
    "ShaderNodeNormalMap": lambda n: n.space not in ("TANGENT", "WORLD"),
    "ShaderNodeVectorTransform": lambda n: "OBJECT" in (n.convert_from, n.convert_to),
    "ShaderNodeTangent": lambda n: n.direction_type == "RADIAL",  # around the generated coordinates' axis
    "ShaderNodeTexImage": lambda n: n.projection != "FLAT",  # box, sphere and tube projections are in object space
    "ShaderNodeOutputMaterial": lambda n: n.inputs["Displacement"].is_linked,
    "ShaderNodeGroup": lambda n: reads_placement(n.node_tree),
    **{kind: lambda n: True for kind in PLACEMENT_NODES},
    **{kind: lambda n: not n.inputs["Vector"].is_linked for kind in GENERATED_BY_DEFAULT},
}


def reads_placement(tree: Any) -> bool:
    """Whether a shader node tree reads where its object is (object, generated or instancer coordinates, object
    info, object space), which differs between an instance and a realized copy; node groups are searched too."""
    return tree is not None and any(
        _PLACEMENT_READERS.get(node.bl_idname, lambda n: False)(node) for node in tree.nodes
    )


def instancer_node_group(name: str, obj: Any, selected: bool, realized: bool = False) -> Any:
    """Points -> Instance on Points (`obj` as an instance, the visible attribute as selection) -> Set Instance Transform
    (-> Realize Instances, for a static mesh realized once)."""
    group = geometry_node_group(name)
    nodes, links = group.nodes, group.links
    inputs, outputs = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    info = nodes.new("GeometryNodeObjectInfo")
    info.transform_space = "ORIGINAL"  # the mesh in its own space: the transform attribute is its whole world matrix
    info.inputs["Object"].default_value = obj
    # an instance of the object: Cycles keeps its geometry between steps
    info.inputs["As Instance"].default_value = True
    on_points = nodes.new("GeometryNodeInstanceOnPoints")
    links.new(inputs.outputs[0], on_points.inputs["Points"])
    links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    if selected:
        links.new(_named(nodes, "BOOLEAN", VISIBLE), on_points.inputs["Selection"])
    transform = nodes.new("GeometryNodeSetInstanceTransform")
    links.new(on_points.outputs["Instances"], transform.inputs["Instances"])
    links.new(_named(nodes, "FLOAT4X4", TRANSFORM), transform.inputs["Transform"])
    last = transform.outputs["Instances"]
    if realized:
        realize = nodes.new("GeometryNodeRealizeInstances")
        links.new(last, realize.inputs["Geometry"])
        last = realize.outputs["Geometry"]
    links.new(last, outputs.inputs[0])
    return group


def geometry_node_group(name: str) -> Any:
    """An empty Geometry Nodes group with one geometry input and one geometry output, for a modifier."""
    group = bpy.data.node_groups.new(name, "GeometryNodeTree")
    group.interface.new_socket(name="Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket(name="Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    return group


def _named(nodes: Any, data_type: str, name: str) -> Any:
    node = nodes.new("GeometryNodeInputNamedAttribute")
    node.data_type = data_type
    node.inputs["Name"].default_value = name
    return node.outputs["Attribute"]


def read_instance_color(material: Any) -> None:
    """The material's bound-colour sockets (:func:`color_sockets`) read each instance's colour attribute."""
    sockets = color_sockets(material)
    if sockets is None:
        return  # the renderer's colour setter said why (a spec error) when it compiled the bindings
    target, alpha = sockets
    nodes, links = material.node_tree.nodes, material.node_tree.links
    attribute = nodes.new("ShaderNodeAttribute")
    attribute.attribute_type = "INSTANCER"
    attribute.attribute_name = COLOR
    links.new(attribute.outputs["Color"], target)
    if alpha is not None:
        links.new(attribute.outputs["Alpha"], alpha)
