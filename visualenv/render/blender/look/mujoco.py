"""MuJoCo's look in Cycles (``physics.look: mujoco``): a model lit as MuJoCo's OpenGL renderer lights it, without noise at 1 sample.

MuJoCo's renderer (``render_gl3.c``) lights a geom by fixed-function OpenGL:
its material's emission times its colour; for each light its ambient, its
diffuse term (colour times ``diffuse * max(n.l, 0)``; a spot's
``cos(angle)**exponent`` inside its cutoff, over its attenuation) and its
specular term (Blinn-Phong), a light that casts shadows only where it reaches;
the headlight is one more light, directional along the camera's view, casting
no shadow; a texture multiplies the sum; the sum is written to the image as it
is, no display transform. With no light at all (not even the headlight), a
global ambient of 0.3.

Cycles at 1 sample with no bounces estimates one light per pixel: a second light,
or a world that lights, turns a body's pixels into a random choice among them
(black speckle), and a side that the one light misses stays black. So here:

* the terms that need no shadow (emission, every light's ambient, the headlight's
  diffuse and specular) are computed in each geom's material and emitted: no
  light is sampled for them, so they have no noise. The headlight's direction is
  the camera's view axis (the normal in camera space), exact for whichever
  camera renders;
* the model's lights are Cycles lights of zero size (a sun, or a spot whose
  light shader gives MuJoCo's cone, exponent and attenuation in place of
  Cycles' fall-off with distance), casting shadows where MuJoCo's cast them;
  their diffuse term is the material's diffuse (no specular lobe). With one such
  light, each pixel's one sample is exact;
* the world lights nothing (only camera rays see it), as MuJoCo's skybox, and no surface lights another (the meshes
  are seen by camera and shadow rays only);
* the spec's own objects (an object standing for a body, a .blend's meshes) are lit as geoms without a material;
* colours are written raw (the 'Raw' view transform, images read as numbers),
  as OpenGL writes them.

Not drawn: the model's lights' specular highlights, reflections (``reflectance``), fog and haze.
"""

from __future__ import annotations

import math
from typing import Any

import bpy

from visualenv.physics.scene import Headlight, LightInfo, PhysicsScene
from visualenv.render.blender.look.materials import tinted_base

#: MuJoCo's global ambient when nothing lights the model (``initLights``: no light, headlight off)
UNLIT_AMBIENT = 0.3
#: a Cycles sun of strength 1 lights a white diffuse surface facing it to 1/pi
SUN_UNIT = math.pi
#: a Cycles spot of 1 W whose shader cancels the fall-off lights a white diffuse surface facing it to 1/(4 pi^2)
SPOT_UNIT = 4.0 * math.pi**2
#: what Blender reads images as (bytes / 255 as they are) and writes colours as (no transform), in this look
RAW_COLORSPACE = "Non-Color"
#: the custom property of a material lit as MuJoCo lights a geom (:func:`light_material`)
LIT = "visualenv_mujoco_lit"


def ambient(scene_data: PhysicsScene) -> tuple[float, float, float]:
    """The ambient light every surface gets: the headlight's (when active) and every light's, or MuJoCo's global
    ambient when nothing lights the model (a light's ambient is drawn unshadowed, where MuJoCo drops it in its shadow)."""
    head = scene_data.headlight
    if not scene_data.lights and not head.active:
        return (UNLIT_AMBIENT,) * 3
    terms = [light.ambient for light in scene_data.lights] + ([head.ambient] if head.active else [])
    return tuple(sum(t[k] for t in terms) for k in range(3))  # type: ignore[return-value]


def light_material(
    mat: Any,
    headlight: Headlight,
    ambient_rgb: tuple[float, float, float],
    *,
    emission: float = 0.0,
    specular: float = 0.5,
    shininess: float = 0.5,
) -> None:
    """`mat` (a Principled material) lit as MuJoCo lights a geom of its material's `emission`, `specular` and
    `shininess` (MuJoCo's for a geom without a material by default): its diffuse lobe only (the model's lights), and
    emitting ``texture * min(colour * (emission + ambient + headlight diffuse * max(n.v, 0)) + headlight specular, 1)``
    (OpenGL clamps the lit colour before the texture multiplies it: a white floor under ambient .4 and a headlight of
    .8 shows its texture, not 1.2 times it).

    The colour is the tint node's (:func:`tinted_base`), so a bound colour recolours every term.
    """
    mat[LIT] = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Specular IOR Level"].default_value = 0.0  # MuJoCo's lights add no Fresnel reflection
    texture, tinted = tinted_base(mat)
    texel = texture.links[0].from_socket if texture.is_linked else (1.0, 1.0, 1.0)
    head_on = headlight.active
    geometry = nodes.new("ShaderNodeNewGeometry")
    normal = _to_camera(nodes, links, geometry.outputs["Normal"], "NORMAL")
    # n.l: Cycles' camera space looks along +Z, the headlight shines back
    toward = _dot(nodes, links, normal, (0.0, 0.0, -1.0))
    facing = _math(nodes, links, "MAXIMUM", toward, 0.0)
    diffuse = [v if head_on else 0.0 for v in headlight.diffuse]
    base = tuple(a + emission for a in ambient_rgb)
    light = _vector(nodes, links, "MULTIPLY_ADD", diffuse, facing, base)
    lit = _vector(nodes, links, "MULTIPLY", tinted, light)
    highlight_rgb = [s * specular if head_on else 0.0 for s in headlight.specular]
    # Blinn-Phong with a local viewer: h between the light (the view axis) and the eye (Incoming)
    if max(highlight_rgb) > 0.0:
        eye = _to_camera(nodes, links, geometry.outputs["Incoming"], "VECTOR")
        half = _vector(nodes, links, "NORMALIZE", _vector(nodes, links, "ADD", eye, (0.0, 0.0, -1.0)))
        power = _math(
            nodes,
            links,
            "POWER",
            _math(nodes, links, "MAXIMUM", _dot(nodes, links, normal, half), 0.0),
            128.0 * shininess,
        )
        lit_side = _math(nodes, links, "GREATER_THAN", toward, 0.0)  # OpenGL: no highlight on a side the light misses
        highlight = _vector(nodes, links, "MULTIPLY", _math(nodes, links, "MULTIPLY", power, lit_side), highlight_rgb)
        lit = _vector(nodes, links, "ADD", lit, _vector(nodes, links, "MULTIPLY", highlight, texel))
    lit = _vector(nodes, links, "MINIMUM", lit, texel)  # texture * min(x, 1) = min(texture * x, texture)
    # only camera and shadow rays see a geom (direct_light_only): its emission lights nothing
    links.new(lit, bsdf.inputs["Emission Color"])
    bsdf.inputs["Emission Strength"].default_value = 1.0


def light_scene(scene: Any, headlight: Headlight, ambient_rgb: tuple[float, float, float]) -> None:
    """Every material of `scene` not lit yet that has a Principled BSDF and no emission of its own (the spec's objects,
    a .blend's) lit as MuJoCo lights a geom without a material, so an object standing for a body looks like one."""
    for obj in scene.objects:
        for slot in obj.material_slots:
            mat = slot.material
            if mat is None or mat.get(LIT) or mat.node_tree is None:
                continue
            bsdf = next((n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
            if (
                bsdf is None
                or bsdf.inputs["Emission Color"].is_linked
                or bsdf.inputs["Emission Strength"].is_linked
                or (
                    bsdf.inputs["Emission Strength"].default_value > 0
                    and max(bsdf.inputs["Emission Color"].default_value[:3]) > 0
                )
            ):
                continue
            light_material(mat, headlight, ambient_rgb)


def light_data(light: LightInfo) -> Any:
    """A Cycles light of zero size lighting as MuJoCo's `light` does (diffuse term), casting shadows where it does."""
    strength = max(max(light.diffuse), 1e-9)
    data = bpy.data.lights.new(light.name, "SUN" if light.directional else "SPOT")
    data.color = tuple(v / strength for v in light.diffuse)
    data.use_shadow = light.castshadow
    if light.directional:
        data.angle = 0.0
        data.energy = SUN_UNIT * strength
        return data
    data.energy = SPOT_UNIT * strength
    data.shadow_soft_size = 0.0
    data.use_soft_falloff = False
    # Cycles' widest cone; MuJoCo's cutoff is the half angle
    data.spot_size = min(math.radians(2.0 * light.cutoff), math.pi)
    data.spot_blend = 0.0
    _spot_shader(data, light)
    return data


def _spot_shader(data: Any, light: LightInfo) -> None:
    """The spot's emission: ``cos(angle)**exponent / (a0 + a1 d + a2 d^2)``, times d^2 to cancel Cycles' fall-off."""
    data.use_nodes = True
    nodes, links = data.node_tree.nodes, data.node_tree.links
    emission = next(n for n in nodes if n.type == "EMISSION")
    # Light Falloff's outputs: Constant = strength d^2, Linear = strength d (each cancels that much fall-off)
    falloff = nodes.new("ShaderNodeLightFalloff")
    falloff.inputs["Smooth"].default_value = 0.0
    # a light's Normal: the direction of the ray leaving it, in its own frame (-Z: its axis); Cycles lights only
    # inside the cone, at most 90 degrees off the axis, so the cosine is not negative
    coords = nodes.new("ShaderNodeTexCoord")
    cone = _math(nodes, links, "POWER", _dot(nodes, links, coords.outputs["Normal"], (0.0, 0.0, -1.0)), light.exponent)
    a0, a1, a2 = light.attenuation
    if (a0, a1, a2) == (1.0, 0.0, 0.0):  # no attenuation: the cone is the fall-off's strength
        links.new(cone, falloff.inputs["Strength"])
        links.new(falloff.outputs["Constant"], emission.inputs["Strength"])
        return
    falloff.inputs["Strength"].default_value = 1.0
    lin = _math(nodes, links, "MULTIPLY", falloff.outputs["Linear"], a1)
    quad = _math(nodes, links, "MULTIPLY_ADD", falloff.outputs["Constant"], a2, lin)
    reach = _math(nodes, links, "DIVIDE", falloff.outputs["Constant"], _math(nodes, links, "ADD", quad, a0))
    links.new(_math(nodes, links, "MULTIPLY", cone, reach), emission.inputs["Strength"])


def backdrop(world: Any) -> None:
    """The world seen by the camera only: it lights nothing, as MuJoCo's skybox and background."""
    if world is None:
        return
    visibility = world.cycles_visibility
    visibility.diffuse = visibility.glossy = visibility.transmission = visibility.scatter = False
    world.cycles.sampling_method = "NONE"


def direct_light_only(scene: Any) -> None:
    """Every mesh of `scene` seen by camera and shadow rays only, as MuJoCo draws no light from one surface onto another.

    Even at 0 bounces Cycles traces a bounce ray from each pixel's surface (for the emission it might hit) and shades
    the surface it hits; with the meshes out of that ray's sight it reaches the world at once, which lights nothing
    here: at 0 bounces the frames do not change and a floor's pixel costs about a tenth less
    (results/benchmarks/light-cost.md); with bounces, no light is thrown from one surface onto another.
    """
    for obj in scene.objects:
        if obj.type == "MESH":
            obj.visible_diffuse = obj.visible_glossy = obj.visible_transmission = obj.visible_volume_scatter = False


def raw_images(scene: Any) -> None:
    """Every image the scene's materials and world read, read as numbers (its bytes / 255), as OpenGL reads a texture."""
    trees = [
        slot.material.node_tree
        for obj in scene.objects
        for slot in obj.material_slots
        if slot.material is not None and slot.material.node_tree is not None
    ]
    if scene.world is not None and scene.world.node_tree is not None:
        trees.append(scene.world.node_tree)
    for tree in trees:
        for node in tree.nodes:
            image = getattr(node, "image", None)
            if image is not None and image.colorspace_settings.name != RAW_COLORSPACE:
                image.colorspace_settings.name = RAW_COLORSPACE


# -- node helpers ------------------------------------------------------------------------------------


def _feed(links: Any, socket: Any, value: Any) -> None:
    """Link `value` (an output socket) into `socket`, or set it (a number or a tuple)."""
    if hasattr(value, "is_output"):
        links.new(value, socket)
    else:
        socket.default_value = value


def _operation(nodes: Any, links: Any, kind: str, output: str, operation: str, inputs: tuple) -> Any:
    """A math node of `kind` doing `operation` on `inputs` (sockets or numbers): its `output` socket."""
    node = nodes.new(kind)
    node.operation = operation
    for socket, value in zip(node.inputs, inputs):
        _feed(links, socket, value)
    return node.outputs[output]


def _math(nodes: Any, links: Any, operation: str, *inputs: Any) -> Any:
    return _operation(nodes, links, "ShaderNodeMath", "Value", operation, inputs)


def _vector(nodes: Any, links: Any, operation: str, *inputs: Any) -> Any:
    return _operation(nodes, links, "ShaderNodeVectorMath", "Vector", operation, inputs)


def _dot(nodes: Any, links: Any, a: Any, b: Any) -> Any:
    return _operation(nodes, links, "ShaderNodeVectorMath", "Value", "DOT_PRODUCT", (a, b))


def _to_camera(nodes: Any, links: Any, vector: Any, kind: str) -> Any:
    node = nodes.new("ShaderNodeVectorTransform")
    node.vector_type = kind
    node.convert_from, node.convert_to = "WORLD", "CAMERA"
    links.new(vector, node.inputs["Vector"])
    return node.outputs["Vector"]
