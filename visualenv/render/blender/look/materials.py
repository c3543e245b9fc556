"""Principled BSDF materials, procedural and image textures, the world background.

Every material is a Principled BSDF node tree. Its base colour is also written
to ``Material.diffuse_color`` so the Workbench engine (which shows that colour)
agrees with Cycles and EEVEE. Procedural textures (noise, voronoi, checker,
wave) read object coordinates times ``scale`` and blend between two colours
(default: the material colour and a darker shade of it); image textures read
the mesh's UV map (generated coordinates when it has none). A bound colour on
a textured material multiplies the texture (:func:`color_writer`).

Depth observations use :func:`depth_material`, a view-layer material override
that emits the camera's Z depth mapped linearly from ``depth_range`` to 0..1,
and :func:`depth_world` (white: the background is "far").
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

import bpy

from visualenv.errors import SpecError
from visualenv.files import MAX_IMAGE_PIXELS, FileSizeError, check_image, image_size
from visualenv.render.plan import Material, Texture, World
from visualenv.source_map import SourceMap


def rgba(color: Sequence[float]) -> tuple[float, float, float, float]:
    c = [float(v) for v in color]
    return (c[0], c[1], c[2], c[3] if len(c) > 3 else 1.0)


def _principled(material: Any) -> Any:
    return (
        next((n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None) if material.node_tree else None
    )


def ensure_node_tree(mat: Any) -> None:
    """Give a new material its node tree: Blender 5.0 gives every new material one; older versions need use_nodes."""
    if mat.node_tree is None:  # pragma: no cover - Blender < 5
        mat.use_nodes = True


def make_material(
    name: str,
    spec: Material,
    *,
    base_dir: Path,
    source: SourceMap,
    path: tuple,
    track: Callable[[Any], Any],
    max_pixels: int = MAX_IMAGE_PIXELS,
) -> Any:
    """A new material for `spec`; `path` locates the material in the spec (for errors); an image texture of more than
    `max_pixels` pixels (read from its header) is refused before Blender reads it."""
    mat = track(bpy.data.materials.new(name))
    ensure_node_tree(mat)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = _principled(mat)
    if bsdf is None:
        nodes.clear()
        out = nodes.new("ShaderNodeOutputMaterial")
        bsdf = nodes.new("ShaderNodeBsdfPrincipled")
        links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    color = rgba(spec.color)
    bsdf.inputs["Base Color"].default_value = color
    bsdf.inputs["Alpha"].default_value = color[3]  # below 1: see-through (EEVEE dithers, Cycles passes rays on)
    bsdf.inputs["Roughness"].default_value = spec.roughness
    bsdf.inputs["Metallic"].default_value = spec.metallic
    if spec.emission is not None:
        bsdf.inputs["Emission Color"].default_value = rgba(spec.emission)
        bsdf.inputs["Emission Strength"].default_value = spec.emission_strength
    mat.diffuse_color = color
    mat.roughness = spec.roughness
    mat.metallic = spec.metallic
    if spec.texture is not None:
        _texture(
            mat,
            bsdf,
            spec,
            spec.texture,
            base_dir=base_dir,
            source=source,
            path=path + ("texture",),
            track=track,
            max_pixels=max_pixels,
        )
    return mat


def _texture(
    mat: Any,
    bsdf: Any,
    material: Material,
    tex: Texture,
    *,
    base_dir: Path,
    source: SourceMap,
    path: tuple,
    track: Callable[[Any], Any],
    max_pixels: int,
) -> None:
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    coords = nodes.new("ShaderNodeTexCoord")
    if tex.type == "image":
        files = list(tex.image) if isinstance(tex.image, tuple) else [str(tex.image)]
        where = (
            [path + ("image", i) for i in range(len(files))] if isinstance(tex.image, tuple) else [path + ("image",)]
        )
        images = [_load_image(base_dir / f, source, at, track, max_pixels) for f, at in zip(files, where)]
        node = nodes.new("ShaderNodeTexImage")
        node.image = images[0]
        if isinstance(tex.image, tuple):
            # the names Blender gave them (a taken name gets .001)
            node[TEXTURE_SET] = "\n".join(image.name for image in images)
        links.new(coords.outputs["UV"], node.inputs["Vector"])
        node["visualenv_needs_uv"] = True
        links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
        return
    kinds = {
        "noise": "ShaderNodeTexNoise",
        "voronoi": "ShaderNodeTexVoronoi",
        "checker": "ShaderNodeTexChecker",
        "wave": "ShaderNodeTexWave",
    }
    node = nodes.new(kinds[tex.type])
    links.new(coords.outputs["Object"], node.inputs["Vector"])
    node.inputs["Scale"].default_value = tex.scale
    if "Detail" in node.inputs:
        node.inputs["Detail"].default_value = tex.detail
    first, second = (
        (rgba(tex.colors[0]), rgba(tex.colors[1]))
        if tex.colors
        else (rgba(material.color), rgba([0.35 * v for v in material.color[:3]]))
    )
    if tex.type == "checker":
        node.inputs["Color1"].default_value = first
        node.inputs["Color2"].default_value = second
        links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
        return
    factor = node.outputs["Distance"] if tex.type == "voronoi" else node.outputs["Fac"]
    mix = nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    # ShaderNodeMix has A/B sockets per data type: the colour pair is the RGBA one
    sockets = [s for s in mix.inputs if s.type == "RGBA"]
    sockets[0].default_value = first
    sockets[1].default_value = second
    links.new(factor, mix.inputs["Factor"])
    result = next(s for s in mix.outputs if s.type == "RGBA")
    links.new(result, bsdf.inputs["Base Color"])


#: the custom property of an image texture node that lists its texture set (image names, in the spec's order)
TEXTURE_SET = "visualenv_texture_set"


def _load_image(
    path: Path, source: SourceMap, where: tuple, track: Callable[[Any], Any], max_pixels: int, what: str = "image"
) -> Any:
    """An image Blender reads, or a located error: a missing file, a folder, an image of more than `max_pixels` pixels
    (read from its header, before Blender allocates them), a file Blender cannot decode (`what`: 'image', 'sky image')."""
    file = path.resolve()
    if not file.is_file():
        raise SpecError(
            [
                source.diagnostic(
                    where,
                    (f"{what} file" if what == "image" else what)
                    + " "
                    + ("is a folder" if file.is_dir() else "not found")
                    + f": {file}",
                )
            ]
        )
    try:
        if image_size(file) is None:
            raise SpecError(
                [
                    source.diagnostic(
                        where,
                        f"cannot read {what} {file}: not an image whose size can be read from its header (PNG, JPEG, "
                        "OpenEXR, Radiance HDR, or a format Pillow reads, such as TIFF, BMP, WebP, TGA)",
                    )
                ]
            )
        check_image(file, max_pixels, "scene.max_image_pixels")
    except (FileSizeError, OSError) as exc:
        raise SpecError([source.diagnostic(where, f"cannot read {what}: {exc}")]) from None
    try:
        image = track(bpy.data.images.load(str(file), check_existing=False))
    except RuntimeError as exc:
        raise SpecError([source.diagnostic(where, f"cannot read {what} {file}: {exc}")]) from None
    if image.size[0] == 0:  # Blender loads lazily and keeps an empty image for a file it cannot decode
        raise SpecError(
            [
                source.diagnostic(
                    where, f"cannot read {what} {file}: not an image format Blender reads (PNG, JPEG, EXR, HDR, ...)"
                )
            ]
        )
    return image


def texture_sets(mat: Any) -> list[tuple[Any, list[Any]]]:
    """(image texture node, its images) for every texture set of `mat`."""
    if mat.node_tree is None:
        return []
    return [
        (node, [bpy.data.images[name] for name in str(node[TEXTURE_SET]).split("\n")])
        for node in mat.node_tree.nodes
        if node.type == "TEX_IMAGE" and TEXTURE_SET in node
    ]


def fix_uv_coordinates(mat: Any, mesh: Any) -> None:
    """Image textures on a mesh without a UV map read generated coordinates instead."""
    if mat is None or mat.node_tree is None or mesh is None or len(getattr(mesh, "uv_layers", ())):
        return
    for node in mat.node_tree.nodes:
        if node.type == "TEX_IMAGE" and node.get("visualenv_needs_uv") and node.inputs["Vector"].is_linked:
            link = node.inputs["Vector"].links[0]
            coords = link.from_node
            mat.node_tree.links.new(coords.outputs["Generated"], node.inputs["Vector"])


TINT = "visualenv tint"  # the node a bound colour writes when a texture drives the base colour
#: the node that adds a batch's per-env distraction shift to a material's colour (its second colour: what a binding writes)
SHIFTED = "visualenv distraction shift"
#: the custom property of a material made for a MuJoCo geom: its MuJoCo material's name (the floor's is 'grid')
MUJOCO_MATERIAL = "visualenv_mujoco_material"


def color_sockets(mat: Any) -> tuple[Any, Any] | None:
    """The sockets a bound colour writes in `mat`: the colour's (Principled base colour, or its tint node's) and the
    alpha's (None when a node drives Alpha). When a texture (or any node) drives the base colour, it is multiplied by
    a tint node (white: the texture unchanged) made here. None when the material has no Principled BSDF. Where a
    distraction shifts the colour (:data:`SHIFTED`), the colour is the one its shift node adds to."""
    bsdf = _principled(mat)
    if bsdf is None:
        return None
    base = bsdf.inputs["Base Color"]
    if base.is_linked and base.links[0].from_node.name not in (TINT, SHIFTED):
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        source = base.links[0].from_socket
        texture, tinted = _tint_node(nodes, TINT, (1.0, 1.0, 1.0, 1.0))
        links.new(source, texture)
        links.new(tinted, base)
    target = [s for s in base.links[0].from_node.inputs if s.type == "RGBA"][1] if base.is_linked else base
    if target.is_linked and target.links[0].from_node.name == SHIFTED:  # a textured colour's tint, shifted
        target = [s for s in target.links[0].from_node.inputs if s.type == "RGBA"][1]
    alpha = None if bsdf.inputs["Alpha"].is_linked else bsdf.inputs["Alpha"]
    return target, alpha


def color_writer(mat: Any) -> Callable[[Sequence[float]], None] | None:
    """What writes a bound colour into `mat`, its sockets (:func:`color_sockets`) found once rather than at every step.

    The colour goes to the Principled base colour (or the tint node multiplying
    a texture), its alpha to Alpha (unless a node drives it), and both to the
    viewport colour. None when the material has no Principled BSDF: a bound
    colour could not show in its render.
    """
    sockets = color_sockets(mat)
    if sockets is None:
        return None
    target, alpha = sockets

    def write(color: Sequence[float]) -> None:
        value = rgba(color)
        target.default_value = value
        if alpha is not None:
            alpha.default_value = value[3]
        mat.diffuse_color = value

    return write


def tint_image(mat: Any, image: Any, *, repeat: bool) -> None:
    """`image`, read at the mesh's UV map texel by texel (repeated, or clamped at its edges), times the material's
    base colour drives the base colour; that colour moves to a tint node (:data:`TINT`), where a bound colour writes."""
    bsdf = _principled(mat)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    node = nodes.new("ShaderNodeTexImage")  # no vector input: the active UV map
    node.image = image
    node.interpolation = "Closest"
    node.extension = "REPEAT" if repeat else "EXTEND"
    texture, tinted = _tint_node(nodes, TINT, tuple(bsdf.inputs["Base Color"].default_value))
    links.new(node.outputs["Color"], texture)
    links.new(tinted, bsdf.inputs["Base Color"])


def tinted_base(mat: Any) -> tuple[Any, Any]:
    """The base colour of `mat` (a Principled material) as a product made by a tint node (:data:`TINT`, where a bound
    colour writes): the node's texture input (linked to a texture, or white) and its output. The node is made here,
    with a white texture input, when nothing drives the base colour."""
    bsdf = _principled(mat)
    base = bsdf.inputs["Base Color"]
    if base.is_linked:
        color_sockets(mat)  # a texture's tint node (made now if another node drives the colour)
    else:
        texture, tinted = _tint_node(mat.node_tree.nodes, TINT, tuple(base.default_value))
        texture.default_value = (1.0, 1.0, 1.0, 1.0)
        mat.node_tree.links.new(tinted, base)
    node = base.links[0].from_node
    texture = [sock for sock in node.inputs if sock.type == "RGBA"][0]
    return texture, base.links[0].from_socket


def see_through(scene: Any) -> bool:
    """Whether any material in `scene` has a Principled alpha below 1."""
    for obj in scene.objects:
        for slot in obj.material_slots:
            bsdf = _principled(slot.material) if slot.material is not None else None
            if bsdf is not None and (bsdf.inputs["Alpha"].is_linked or bsdf.inputs["Alpha"].default_value < 1.0):
                return True
    return False


#: names of the nodes an image sky's bindings write
SKY_MAPPING, SKY_TINT = "visualenv sky mapping", "visualenv sky tint"
#: the width of the map by which Cycles picks directions toward the bright parts of an image sky
SKY_MAP_RESOLUTION = 512


def _tint_node(nodes: Any, name: str, tint: Any) -> tuple[Any, Any]:
    """A Mix node that multiplies a colour by `tint` (its second RGBA input, which a colour binding writes): the
    colour input to link a texture or sky into, and the tinted output."""
    mix = nodes.new("ShaderNodeMix")
    mix.name = name
    mix.data_type = "RGBA"
    mix.blend_type = "MULTIPLY"
    mix.inputs["Factor"].default_value = 1.0
    texture, tint_socket = [sock for sock in mix.inputs if sock.type == "RGBA"]
    tint_socket.default_value = tint
    return texture, next(sock for sock in mix.outputs if sock.type == "RGBA")


def make_world(
    name: str,
    spec: World,
    track: Callable[[Any], Any],
    *,
    base_dir: Path | None = None,
    source: SourceMap | None = None,
    max_pixels: int = MAX_IMAGE_PIXELS,
) -> Any:
    """A world with a uniform background, or an image sky: an environment map turned by a Mapping node and tinted.

    The image lights the scene and shows behind it (Cycles and EEVEE; Workbench shows the tint colour).
    """
    world = track(bpy.data.worlds.new(name))
    tint = rgba(spec.tint)
    set_background(world, tint, spec.strength)
    if spec.image is None:
        return world
    assert base_dir is not None and source is not None, "an image sky is read relative to the spec"
    image = _load_image(base_dir / spec.image, source, ("scene", "world", "image"), track, max_pixels, "sky image")
    nodes, links = world.node_tree.nodes, world.node_tree.links
    bg = next(n for n in nodes if n.type == "BACKGROUND")
    coords = nodes.new("ShaderNodeTexCoord")
    mapping = nodes.new("ShaderNodeMapping")
    mapping.name = SKY_MAPPING
    mapping.vector_type = "POINT"
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    texture, tinted = _tint_node(nodes, SKY_TINT, tint)
    links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    links.new(env.outputs["Color"], texture)
    links.new(tinted, bg.inputs["Color"])
    rotation = list(spec.rotation) if isinstance(spec.rotation, tuple) else [0.0, 0.0, spec.rotation]
    mapping.inputs["Rotation"].default_value = rotation
    # Cycles samples the sky by an importance map of it: its automatic size cost seconds at every env start and
    # again whenever a binding changed the world; 512 wide costs little (results/benchmarks/spec-features-cost.md)
    world.cycles.sampling_method = "MANUAL"
    world.cycles.sample_map_resolution = SKY_MAP_RESOLUTION
    return world


#: the world's node that shows a model's skybox to camera rays only (the batch renderer: it lights nothing)
SKYBOX = "visualenv-skybox"


def show_skybox(world: Any, image: Any) -> None:
    """Show `image` (an equirectangular sky) behind the scene, to camera rays only, as MuJoCo draws its skybox.

    `world` is one colour (the default world). Every other ray (diffuse, glossy,
    shadow) still sees its Background, so the lighting is the same as without the
    skybox: MuJoCo's skybox lights nothing.
    """
    nodes, links = world.node_tree.nodes, world.node_tree.links
    bg = next(n for n in nodes if n.type == "BACKGROUND")
    out = next(n for n in nodes if n.type == "OUTPUT_WORLD")
    env = nodes.new("ShaderNodeTexEnvironment")
    env.name = SKYBOX
    env.image = image
    sky = nodes.new("ShaderNodeBackground")
    sky.inputs["Strength"].default_value = 1.0
    path = nodes.new("ShaderNodeLightPath")
    mix = nodes.new("ShaderNodeMixShader")
    links.new(env.outputs["Color"], sky.inputs["Color"])
    links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
    links.new(bg.outputs["Background"], mix.inputs[1])
    links.new(sky.outputs["Background"], mix.inputs[2])
    links.new(mix.outputs["Shader"], out.inputs["Surface"])
    # Cycles samples a one-colour world without an importance map; with a texture in its shader it would make one
    # (seconds at start, and other noise: the model 1-2 levels darker at 1 sample). No map: the same pixels as before
    world.cycles.sampling_method = "NONE"


def world_writer(world: Any, prop: str) -> Callable[[Sequence[float]], None] | str:
    """What writes a World binding (strength, rotation or color) into `world`; a string says why it cannot."""
    nodes: Any = world.node_tree.nodes if world is not None and world.node_tree is not None else None
    bg = next((n for n in nodes if n.type == "BACKGROUND"), None) if nodes is not None else None
    if bg is None:
        return "the scene's world has no Background node to bind: give the spec a 'world'"
    if prop == "strength":
        socket = bg.inputs["Strength"]

        def write_strength(v: Sequence[float]) -> None:
            socket.default_value = v[0]

        return write_strength
    if prop == "rotation":
        mapping = nodes.get(SKY_MAPPING)
        if mapping is None:
            return "'rotation' turns an image sky: give the world an 'image'"
        rotation = mapping.inputs["Rotation"]

        def write_rotation(v: Sequence[float]) -> None:
            rotation.default_value = v

        return write_rotation
    if prop == "color":
        mix = nodes.get(SKY_TINT)
        target = [sock for sock in mix.inputs if sock.type == "RGBA"][1] if mix is not None else bg.inputs["Color"]

        def write_color(v: Sequence[float]) -> None:
            target.default_value = rgba(v)
            if mix is None:
                world.color = tuple(v[:3])

        return write_color
    return f"the world takes 'strength', 'rotation' and 'color', not '{prop}'"


def set_background(world: Any, color: tuple, strength: float) -> None:
    """Light the world in one colour: its Background node (made, in place of its nodes, if it has none) and its viewport colour."""
    nodes = world.node_tree.nodes
    bg = next((n for n in nodes if n.type == "BACKGROUND"), None)
    if bg is None:
        nodes.clear()
        out = nodes.new("ShaderNodeOutputWorld")
        bg = nodes.new("ShaderNodeBackground")
        world.node_tree.links.new(bg.outputs["Background"], out.inputs["Surface"])
    bg.inputs["Color"].default_value = color
    bg.inputs["Strength"].default_value = strength
    world.color = color[:3]


def depth_world(name: str, track: Callable[[Any], Any]) -> Any:
    """White background: a ray that hits nothing is as far as it gets (255)."""
    world = track(bpy.data.worlds.new(name))
    set_background(world, (1.0, 1.0, 1.0, 1.0), 1.0)
    return world


def override_material(name: str, track: Callable[[Any], Any]) -> tuple[Any, Any, Any, Any]:
    """A new material with nothing but its output node (for a render that overrides every material): the material,
    its nodes, its links and the output."""
    mat = track(bpy.data.materials.new(name))
    ensure_node_tree(mat)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    return mat, nodes, links, nodes.new("ShaderNodeOutputMaterial")


def depth_material(
    name: str, track: Callable[[Any], Any], *, along_ray: bool = False
) -> tuple[Any, Callable[[float, float], None], Callable[[Any], None]]:
    """An emission material of clamp((z - near) / (far - near)), a setter for near/far and one for the camera's forward axis.

    z is the camera's view Z depth. With `along_ray` it is computed from the camera
    ray instead, as its length times its cosine to the forward axis (given by the
    setter, in world space): the same depth, but measured from wherever the ray
    starts, which a batch's custom camera moves to each env's copy (the Camera
    Data node measures from the scene camera alone).
    """
    mat, nodes, links, out = override_material(name, track)
    remap = nodes.new("ShaderNodeMapRange")
    remap.clamp = True
    remap.inputs["To Min"].default_value = 0.0
    remap.inputs["To Max"].default_value = 1.0
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    forward = None
    if along_ray:
        path, geometry = nodes.new("ShaderNodeLightPath"), nodes.new("ShaderNodeNewGeometry")
        forward = nodes.new("ShaderNodeVectorMath")
        forward.operation = "DOT_PRODUCT"  # incoming points back to the camera: its dot with -forward is the cosine
        depth = nodes.new("ShaderNodeMath")
        depth.operation = "MULTIPLY"
        links.new(geometry.outputs["Incoming"], forward.inputs[0])
        links.new(forward.outputs["Value"], depth.inputs[0])
        links.new(path.outputs["Ray Length"], depth.inputs[1])
        links.new(depth.outputs["Value"], remap.inputs["Value"])
    else:
        cam = nodes.new("ShaderNodeCameraData")
        links.new(cam.outputs["View Z Depth"], remap.inputs["Value"])
    links.new(remap.outputs["Result"], emit.inputs["Color"])
    links.new(emit.outputs["Emission"], out.inputs["Surface"])

    def set_range(near: float, far: float) -> None:
        remap.inputs["From Min"].default_value = near
        remap.inputs["From Max"].default_value = max(far, near + 1e-6)

    def set_forward(axis: Any) -> None:
        if forward is not None:
            forward.inputs[1].default_value = tuple(-float(c) for c in axis)

    return mat, set_range, set_forward
