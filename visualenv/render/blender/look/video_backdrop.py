"""The Distracting Control Suite's video backgrounds on the backdrop: each env's frame in one image, seen as MuJoCo's
sky shows it.

The suite writes a frame, resized to a square, into MuJoCo's skybox texture, which MuJoCo repeats on the six faces of
a cube about the camera (a square cube texture: one image for every face). Here each env's current frame is a tile
of one image (:class:`VideoAtlas`, a tile per env of a batch), and the backdrop's shader looks it up where the ray's
direction meets that cube (:func:`cube_lookup`): the tile the backdrop's instance names (an attribute), the same image
on every face, fixed in the world as the skybox is.

When an env's frame changes, the frames are written into a new image and the lookup turned to it. Cycles' persistent
data never reloads an image it was given once (its pixels may change; it keeps them all), and it knows an image by its
address: a new image made where a removed one lay would show the removed one's pixels, and a removed image it still
holds is memory freed under it. So no image Cycles' session was given is removed while that session lives: once they
pass :data:`RETAINED_IMAGES` or :data:`RETAINED_BYTES` the session is let go (the scene's next render builds it afresh,
the same frame), and only then are the images the lookups no longer read removed.
"""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

import bpy
import numpy as np

from visualenv.render.blender.look.mujoco import RAW_COLORSPACE
from visualenv.render.videos import FRAME_SIDE, load_frame

#: the backdrop's attribute that names its env's tile (column, row) and whether it shows a video (1) or not (0)
VIDEO = "visualenv_background_video"
#: the atlas's largest side in pixels: a batch of more than 64 envs gets smaller tiles (N = 256: 128 pixels)
ATLAS_SIDE = 2048
#: the images (their pixels' bytes, their count) Cycles' session may be given before it is let go: a single env's frame
#: is 256 KiB, held twice until then (Blender's image and Cycles' copy); each render's sync walks all Cycles keeps, and
#: building the session anew costs about one DMC step
RETAINED_BYTES, RETAINED_IMAGES = 64 * 2**20, 256


class VideoAtlas:
    """One image holding a tile per env in a grid (each :data:`FRAME_SIDE` pixels square, smaller where the image
    would pass :data:`ATLAS_SIDE`); :meth:`show` writes frames."""

    def __init__(
        self,
        name: str,
        count: int,
        scene: Any,
        raw: bool = False,
        own: Callable[[Any], object] = lambda image: None,
    ) -> None:
        """`scene`: where the frames are rendered (its Cycles session is let go now and then). `raw`: the scene writes
        colours as they are (MuJoCo's look, as MuJoCo shows a texture's bytes), else through sRGB: either way a frame's
        pixel is shown as its bytes. `own` is given every image made, for the renderer to remove at close."""
        self.columns = math.ceil(math.sqrt(count))
        self.rows = math.ceil(count / self.columns)
        #: a tile's side in pixels
        self.side = side = min(FRAME_SIDE, ATLAS_SIDE // self.columns)
        self._name, self._scene, self._raw, self._own = name, scene, raw, own
        self._given = 0  # the images made since Cycles' session began
        self._image_bytes = self.rows * self.columns * side * side * 4  # as Cycles keeps it: 4 bytes a pixel
        #: the image the lookups read now, and the nodes that read it (:func:`cube_lookup`)
        self._retired: list[Any] = []  # images the lookups read before: removed once Cycles' session is let go
        self.image = self._new_image()
        self.nodes: list[Any] = []
        self._pixels = np.ones((self.rows * side, self.columns * side, 4), dtype=np.float32)
        self._shown = [""] * count

    def tiles(self) -> np.ndarray:
        """``(count, 2)``: each env's tile, its column and row."""
        k = np.arange(len(self._shown))
        return np.stack([k % self.columns, k // self.columns], axis=1).astype(np.float32)

    def show(self, files: Sequence[str]) -> None:
        """Each env's frame (its file; "" leaves its tile) in its tile, the image written once if any changed."""
        side, changed = self.side, False
        for k, file in enumerate(files):
            if not file or file == self._shown[k]:
                continue
            row, column = divmod(k, self.columns)
            frame = load_frame(file, side)[::-1].astype(np.float32) / 255.0  # Blender's rows run from the bottom
            self._pixels[row * side : (row + 1) * side, column * side : (column + 1) * side, :3] = frame
            self._shown[k] = file
            changed = True
        if changed:
            image = self._new_image()
            image.pixels.foreach_set(self._pixels.ravel())
            image.update()
            self._retired.append(self.image)
            self.image = image
            for node in self.nodes:
                node.image = image

    def _new_image(self) -> Any:
        """A new image for the lookups (Cycles' session let go first where it was given enough)."""
        side = self.side
        if self._given >= RETAINED_IMAGES or self._given * self._image_bytes > RETAINED_BYTES:
            self._let_cycles_go()
        image = bpy.data.images.new(self._name, self.columns * side, self.rows * side, alpha=False)
        image.colorspace_settings.name = RAW_COLORSPACE if self._raw else "sRGB"
        self._own(image)
        self._given += 1
        return image

    def _let_cycles_go(self) -> None:
        """Free Cycles' session (and every image it keeps; turning persistent data off frees it at once, and the next
        render, with it on again, builds the scene anew), then the images no lookup reads."""
        render = self._scene.render
        if render.use_persistent_data:
            render.use_persistent_data = False
            render.use_persistent_data = True
        for image in self._retired:
            bpy.data.images.remove(image)
        self._retired.clear()
        self._given = 0


def cube_lookup(nodes: Any, links: Any, direction: Any, tile: Any, atlas: VideoAtlas) -> Any:
    """An Image Texture node of `atlas` at the point of the env's tile (`tile`: a vector socket, its column and row in X
    and Y) where `direction` (a vector socket) meets the cube about the camera: the face its largest component picks,
    the point's other two coordinates over that component (a skybox's gnomonic map), the image upright on the side
    faces. Returns the node (its Color output)."""

    def math_node(operation: str, *inputs: Any) -> Any:
        node = nodes.new("ShaderNodeMath")
        node.operation = operation
        for socket, given in zip(node.inputs, inputs):
            if isinstance(given, (int, float)):
                socket.default_value = float(given)
            else:
                links.new(given, socket)
        return node.outputs[0]

    split = nodes.new("ShaderNodeSeparateXYZ")
    links.new(direction, split.inputs[0])
    x, y, z = split.outputs["X"], split.outputs["Y"], split.outputs["Z"]
    ax, ay, az = (math_node("ABSOLUTE", c) for c in (x, y, z))
    largest = math_node("MAXIMUM", ax, math_node("MAXIMUM", ay, az))
    on_x = math_node("GREATER_THAN", ax, math_node("MAXIMUM", ay, az))  # 1 on the faces +-x
    not_x = math_node("SUBTRACT", 1.0, on_x)
    on_y = math_node("MULTIPLY", not_x, math_node("GREATER_THAN", ay, az))
    on_z = math_node("SUBTRACT", not_x, on_y)

    def weighted(*terms: tuple[Any, Any]) -> Any:
        total = None
        for weight, value in terms:
            term = math_node("MULTIPLY", weight, value)
            total = term if total is None else math_node("ADD", total, term)
        return total

    # across each face, looking out from the cube's centre with +z up: +x's right is -y, +y's is +x, +z's is +x
    across = weighted(
        (on_x, math_node("MULTIPLY", math_node("SIGN", x), math_node("MULTIPLY", y, -1.0))),
        (on_y, math_node("MULTIPLY", math_node("SIGN", y), x)),
        (on_z, x),
    )
    upward = weighted(
        (math_node("ADD", on_x, on_y), z),
        (on_z, math_node("MULTIPLY", math_node("SIGN", z), math_node("MULTIPLY", y, -1.0))),
    )
    tile_split = nodes.new("ShaderNodeSeparateXYZ")
    links.new(tile, tile_split.inputs[0])
    margin = 0.5 / atlas.side  # half a pixel: a lookup never blends a neighbouring tile

    def in_atlas(coordinate: Any, tile_index: Any, tiles: int) -> Any:
        inside = math_node("ADD", math_node("MULTIPLY", math_node("DIVIDE", coordinate, largest), 0.5), 0.5)
        inside = math_node("MINIMUM", math_node("MAXIMUM", inside, margin), 1.0 - margin)
        return math_node("DIVIDE", math_node("ADD", tile_index, inside), float(tiles))

    uv = nodes.new("ShaderNodeCombineXYZ")
    links.new(in_atlas(across, tile_split.outputs["X"], atlas.columns), uv.inputs["X"])
    links.new(in_atlas(upward, tile_split.outputs["Y"], atlas.rows), uv.inputs["Y"])
    texture = nodes.new("ShaderNodeTexImage")
    texture.image = atlas.image
    atlas.nodes.append(texture)
    texture.interpolation = "Linear"
    texture.extension = "EXTEND"
    links.new(uv.outputs[0], texture.inputs["Vector"])
    return texture
