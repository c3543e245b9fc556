"""N moving cylinders drawn by one Geometry Nodes instancer against one mesh whose vertices numpy writes each step.

    python benchmarks/moving_mesh_vs_instances.py [--envs 1024] [--mode instanced|merged] [--segments 8] [--renders 15]

A standalone bpy script (no visualenv): Cycles on the CPU, 1 sample, an 8x8 image. It prints the write, the render
call with every cylinder moved and with nothing moved, and the update per cylinder (write + moved - still). The
record: results/benchmarks/render-host-cost-vm.md (moving meshes stay instances: one mesh's rebuild costs about what
the instances' sync costs).
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any, Callable

import bpy
import numpy as np


def scene() -> Any:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    current = bpy.context.scene
    current.render.engine = "CYCLES"
    current.cycles.device = "CPU"
    current.cycles.samples = 1
    current.cycles.max_bounces = 0
    current.cycles.use_denoising = False
    current.render.resolution_x = current.render.resolution_y = 8
    current.render.use_persistent_data = True
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    current.collection.objects.link(camera)
    camera.location = (0.0, 0.0, 50.0)
    current.camera = camera
    return current


def poses(t: float, grid: np.ndarray) -> np.ndarray:
    """Each cylinder's world matrix ``(N, 4, 4)``: turned about Y and shifted along X, on its grid place."""
    n = len(grid)
    angle = np.sin(t + np.arange(n) * 0.1).astype(np.float32)
    matrices = np.zeros((n, 4, 4), dtype=np.float32)
    matrices[:, 0, 0] = matrices[:, 2, 2] = np.cos(angle)
    matrices[:, 0, 2], matrices[:, 2, 0] = np.sin(angle), -np.sin(angle)
    matrices[:, 1, 1] = matrices[:, 3, 3] = 1.0
    matrices[:, 0, 3], matrices[:, 1, 3] = grid[:, 0] + angle, grid[:, 1]
    return matrices


def instanced(current: Any, part: Any, grid: np.ndarray) -> Callable[[float], None]:
    """One point per cylinder under Instance on Points, posed by a 4x4 point attribute (as visualenv's instancers are)."""
    points = bpy.data.meshes.new("points")
    points.vertices.add(len(grid))
    points.attributes.new("pose", "FLOAT4X4", "POINT")
    holder = bpy.data.objects.new("instances", points)
    current.collection.objects.link(holder)
    tree = bpy.data.node_groups.new("instances", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = tree.nodes, tree.links
    info = nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = part
    info.inputs["As Instance"].default_value = True
    on_points, pose = nodes.new("GeometryNodeInstanceOnPoints"), nodes.new("GeometryNodeInputNamedAttribute")
    pose.data_type = "FLOAT4X4"
    pose.inputs["Name"].default_value = "pose"
    transform = nodes.new("GeometryNodeSetInstanceTransform")
    links.new(nodes.new("NodeGroupInput").outputs[0], on_points.inputs["Points"])
    links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    links.new(on_points.outputs[0], transform.inputs["Instances"])
    links.new(pose.outputs[0], transform.inputs["Transform"])
    links.new(transform.outputs[0], nodes.new("NodeGroupOutput").inputs[0])
    holder.modifiers.new("instances", "NODES").node_group = tree

    def write(t: float) -> None:
        points.attributes["pose"].data.foreach_set("value", poses(t, grid).transpose(0, 2, 1).ravel())
        points.update()
    return write


def merged(current: Any, part: Any, grid: np.ndarray) -> Callable[[float], None]:
    """Every cylinder's copy in one mesh, each vertex placed by numpy and written with one foreach_set."""
    source, n = part.data, len(grid)
    count = len(source.vertices)
    local = np.empty(count * 3, dtype=np.float32)
    source.attributes["position"].data.foreach_get("vector", local)
    local = local.reshape(count, 3)
    corners = np.empty(len(source.loops), dtype=np.int32)
    source.loops.foreach_get("vertex_index", corners)
    starts = np.empty(len(source.polygons), dtype=np.int32)
    source.polygons.foreach_get("loop_start", starts)
    mesh = bpy.data.meshes.new("merged")
    mesh.vertices.add(n * count)
    mesh.loops.add(n * len(corners))
    mesh.polygons.add(n * len(starts))
    mesh.loops.foreach_set("vertex_index", (corners[None] + (np.arange(n) * count)[:, None]).ravel())
    mesh.polygons.foreach_set("loop_start", (starts[None] + (np.arange(n) * len(corners))[:, None]).ravel())
    mesh.update(calc_edges=True)
    current.collection.objects.link(bpy.data.objects.new("merged", mesh))
    positions = mesh.attributes["position"]

    def write(t: float) -> None:
        matrices = poses(t, grid)
        placed = np.matmul(matrices[:, None, :3, :3], local[None, :, :, None])[..., 0] + matrices[:, None, :3, 3]
        positions.data.foreach_set("vector", placed.ravel())
        mesh.update_tag()
    return write


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=1024)
    parser.add_argument("--mode", choices=("instanced", "merged"), default="instanced")
    parser.add_argument("--segments", type=int, default=8, help="the cylinder's sides")
    parser.add_argument("--renders", type=int, default=15)
    args = parser.parse_args()
    current = scene()
    bpy.ops.mesh.primitive_cylinder_add(vertices=args.segments, radius=0.2, depth=1.0)
    part = bpy.context.active_object
    part.hide_render = True
    columns = 32
    grid = np.stack(np.meshgrid(np.arange(columns), np.arange(-(-args.envs // columns))), -1).reshape(-1, 2)[:args.envs]
    write = (instanced if args.mode == "instanced" else merged)(current, part, grid.astype(np.float32) * 5)
    render = lambda: bpy.ops.render.render(write_still=False)  # noqa: E731
    for i in range(3):
        write(float(i))
        render()
    writes, moved, still = [], [], []
    for i in range(args.renders):
        start = time.perf_counter()
        write(0.1 * i)
        written = time.perf_counter()
        render()
        writes.append(written - start)
        moved.append(time.perf_counter() - written)
    for _ in range(args.renders):
        start = time.perf_counter()
        render()
        still.append(time.perf_counter() - start)
    w, m, s = (1000 * statistics.median(values) for values in (writes, moved, still))
    print(f"{args.mode}, {args.envs} cylinders of {len(part.data.vertices)} vertices: write {w:.2f} ms, moved {m:.1f} ms, "
          f"still {s:.1f} ms, update {w + m - s:.1f} ms = {1000 * (w + m - s) / args.envs:.2f} us a cylinder")


if __name__ == "__main__":
    main()
