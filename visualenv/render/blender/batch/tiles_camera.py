"""The batch's custom camera: one image of ``cols x rows`` tiles, tile k seen from env k's copy of the scene.

A Cycles custom camera (an OSL camera shader, :data:`TILES_OSL`) sits at the observation camera's pose and
sends the rays of tile k from the camera's pose shifted to copy k's place on the grid of copies, with the spec
camera's lens (:func:`lens`). A camera the state turns gets a shader with every env's own rotation
(:func:`turning_source`). :func:`make_tiles_camera` builds one; :func:`grid_shape` and :func:`tile` lay the
tiles out and cut them apart.
"""

from __future__ import annotations

import math
from typing import Any

import bpy
import numpy as np
from mathutils import Matrix, Vector

from visualenv.compat.blender import compile_camera_shader
from visualenv.render.blender.runtime.log import blender_output


#: the tiles shader, written once for both cameras: @NAME@ and the parts a turning camera adds (@ROTATIONS@, its
#: parameters; @TABLE@, them as one array; @TURN@, the turn of the ray's position and direction by env's rotation)
_TILES_TEMPLATE = r"""
// visualenv: one tile of the image per env. Tile k (row-major from the top left) looks
// from the camera's pose shifted by k's place on the grid of copies@TURNED@.
shader @NAME@(
    int cols = 1, int count = 1, int first = 0, int ortho = 0,
    float half_w = 0.5, float half_h = 0.5, float shift_x = 0, float shift_y = 0,
    float ax = 0, float ay = 0, float az = 0, float bx = 0, float by = 0, float bz = 0,
    int grid = 1,
@ROTATIONS@    output point position = 0, output vector direction = 0, output color throughput = 1)
{
@TABLE@    point r = camera_shader_raster_position();
    int rows = (count + cols - 1) / cols;
    float fx = r[0] * cols;
    float fy = (1.0 - r[1]) * rows;
    int c = clamp((int)floor(fx), 0, cols - 1);
    int t = clamp((int)floor(fy), 0, rows - 1);
    int k = t * cols + c;
    if (k >= count) {
        throughput = 0;
    } else {
        int env = first + k;
        float u = (fx - c) * 2.0 - 1.0;
        float v = 1.0 - (fy - t) * 2.0;
        vector offset = (env % grid) * vector(ax, ay, az) + (env / grid) * vector(bx, by, bz);
        float x = u * half_w + shift_x;
        float y = v * half_h + shift_y;
        vector p = ortho ? vector(x, y, 0) : vector(0, 0, 0);
        vector d = ortho ? vector(0, 0, 1) : normalize(vector(x, y, 1.0));
@TURN@        position = point(offset[0] + p[0], offset[1] + p[1], offset[2] + p[2]);
        direction = d;
    }
}
"""

_TURN = """        int i = 4 * clamp(env, 0, @LAST@);
        float w = R[i];
        vector q = vector(R[i + 1], R[i + 2], R[i + 3]);
        p = p + 2.0 * w * cross(q, p) + 2.0 * cross(q, cross(q, p));
        d = d + 2.0 * w * cross(q, d) + 2.0 * cross(q, cross(q, d));
"""

#: the tiles shader of a camera that does not turn
TILES_OSL = (
    _TILES_TEMPLATE.replace("@NAME@", "visualenv_tiles")
    .replace("@TURNED@", "")
    .replace("@ROTATIONS@", "")
    .replace("@TABLE@", "")
    .replace("@TURN@", "")
)

TURNING_NAME = "visualenv_tiles_turning"


def turning_source(num_envs: int) -> str:
    """The tiles shader for a camera the state turns: as :data:`TILES_OSL`, and each env's rays are turned by its
    own camera's rotation relative to this camera's, in Cycles' camera space: a unit quaternion an env (r<k>_0 its
    w, r<k>_1..3 its x, y, z), every rotation starting as the identity. A change of rotations compiles the shader
    again, and four parameters an env compile faster than nine (a 3x3 matrix;
    results/benchmarks/batched-suns-and-cameras.md)."""
    names = [f"r{k}_{i}" for k in range(num_envs) for i in range(4)]
    rotations = "".join(f"    float r{k}_{i} = {1 if i == 0 else 0},\n" for k in range(num_envs) for i in range(4))
    return (
        _TILES_TEMPLATE.replace("@NAME@", TURNING_NAME)
        .replace("@TURNED@", " and turned by the env's own camera rotation")
        .replace("@ROTATIONS@", rotations)
        .replace("@TABLE@", f"    float R[{4 * num_envs}] = {{{', '.join(names)}}};\n")
        .replace("@TURN@", _TURN.replace("@LAST@", str(num_envs - 1)))
    )


def tiles_text(turning: int = 0) -> Any:
    """The tiles shader's text datablock: TILES_OSL, or for a camera that turns, :func:`turning_source` for `turning` envs."""
    name = f"{TURNING_NAME}{turning}.osl" if turning else "visualenv_tiles.osl"
    source = turning_source(turning) if turning else TILES_OSL
    text = bpy.data.texts.get(name)
    if text is None or text.as_string() != source:
        text = text or bpy.data.texts.new(name)
        text.clear()
        text.write(source)
    return text


def compile_tiles_camera(camera: Any, scene: Any) -> None:
    """Compile the custom camera's shader, giving its data the shader's parameters; Cycles' messages go with the error."""
    with blender_output() as output:  # Cycles reports each compilation ("OSL shader compilation succeeded")
        try:
            compile_camera_shader(camera, scene)
            return
        except RuntimeError as exc:
            error = str(exc)
    raise RuntimeError(
        "Cycles could not compile the batch's custom camera shader: " + "; ".join(output.lines or [error])
    )


def make_tiles_camera(
    scene: Any, name: str, source: Any, shader: Any, width: int, height: int, spacing: float, cols: int
) -> Any:
    """A custom camera in `scene` at `source`'s pose, with its lens and clipping, showing every env's tile of a
    `width` x `height` view through `shader`, for copies `spacing` apart in `cols` columns."""
    data = bpy.data.cameras.new(name)
    data.type = "CUSTOM"
    data.custom_mode = "INTERNAL"
    data.custom_shader = shader
    data.clip_start, data.clip_end = source.data.clip_start, source.data.clip_end
    camera = bpy.data.objects.new(name, data)
    scene.collection.objects.link(camera)
    pose = source.matrix_world.normalized()
    camera.matrix_world = pose
    # Blender compiles a camera shader for the context scene's engine (a batch's is Cycles)
    if scene.render.engine != "CYCLES":
        scene.render.engine = "CYCLES"
    compile_tiles_camera(camera, scene)
    params = data.cycles_custom
    half_w, half_h, shift_x, shift_y, ortho = lens(source.data, width, height)
    # world offsets of one grid column and row, in Cycles' camera space (x right, y up, z forward)
    to_camera = Matrix.Diagonal((1.0, 1.0, -1.0)) @ pose.to_3x3().inverted()
    a = to_camera @ Vector((spacing, 0.0, 0.0))
    b = to_camera @ Vector((0.0, spacing, 0.0))
    for key, value in dict(
        cols=cols,
        grid=cols,
        ortho=int(ortho),
        half_w=half_w,
        half_h=half_h,
        shift_x=shift_x,
        shift_y=shift_y,
        ax=a.x,
        ay=a.y,
        az=a.z,
        bx=b.x,
        by=b.y,
        bz=b.z,
    ).items():
        params[key] = value
    return camera


def lens(data: Any, width: int, height: int) -> tuple[float, float, float, float, bool]:
    """(half width, half height, shift x, shift y, orthographic) of a camera's view of a width x height image.

    Perspective: tangents of the half angles (at distance 1); orthographic: half sizes.
    Follows Blender's sensor fit: 'AUTO' fits the larger image side to the sensor width.
    """
    ortho = data.type == "ORTHO"
    if data.type not in ("PERSP", "ORTHO"):
        raise ValueError(f"a batch renders perspective and orthographic cameras, not {data.type.lower()} ones")
    fit = data.sensor_fit
    horizontal = fit == "HORIZONTAL" or (fit == "AUTO" and width >= height)
    if ortho:
        size = data.ortho_scale / 2
    else:
        sensor = data.sensor_height if fit == "VERTICAL" else data.sensor_width
        size = sensor / 2 / data.lens
    if horizontal:
        half_w, half_h = size, size * height / width
    else:
        half_h, half_w = size, size * width / height
    larger = 2 * max(half_w, half_h)
    return half_w, half_h, data.shift_x * larger, data.shift_y * larger, ortho


def grid_shape(count: int) -> tuple[int, int]:
    """(cols, rows) of the most square grid holding `count` tiles."""
    cols = math.ceil(math.sqrt(count))
    return cols, math.ceil(count / cols)


def tile(image: np.ndarray, count: int, height: int, width: int) -> np.ndarray:
    """(count, height, width, C): the tiles of `image` in row-major order from the top left."""
    cols = image.shape[1] // width
    rows = image.shape[0] // height
    tiles = image.reshape(rows, height, cols, width, -1).swapaxes(1, 2).reshape(rows * cols, height, width, -1)
    return tiles[:count]


def tiles_camera_check() -> dict[str, Any]:
    """Compile the batch's custom camera on a throwaway camera and render one 16x16 frame through it (``visualenv info``).

    Raises what a batch would raise when this Blender cannot (no OSL, no ``oslquery``).
    """
    data = bpy.data.cameras.new("visualenv-tiles-probe")
    camera = bpy.data.objects.new("visualenv-tiles-probe", data)
    scene = bpy.data.scenes.new("visualenv-tiles-probe")
    try:
        scene.collection.objects.link(camera)
        scene.camera = camera
        scene.render.engine = "CYCLES"
        scene.render.resolution_x = scene.render.resolution_y = 16
        scene.cycles.samples = 1
        data.type, data.custom_mode, data.custom_shader = "CUSTOM", "INTERNAL", tiles_text()
        compile_tiles_camera(camera, scene)
        bpy.ops.render.render(scene=scene.name)
        return {"available": True}
    finally:
        bpy.data.scenes.remove(scene)
        bpy.data.objects.remove(camera)
        bpy.data.cameras.remove(data)


def rotation_of(matrix: Matrix) -> np.ndarray:
    """The rotation of a 4x4 ``mathutils.Matrix``, in float64, its columns normalised (no scale)."""
    return unit_columns(np.array(matrix.to_3x3(), dtype=np.float64))


def unit_columns(rotations: np.ndarray) -> np.ndarray:
    """3x3 matrices (``(..., 3, 3)``) with each column divided by its length: their rotation, without scale."""
    return rotations / np.linalg.norm(rotations, axis=-2, keepdims=True)
