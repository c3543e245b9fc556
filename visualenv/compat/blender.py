"""Blender's behaviour that visualenv works around, in one place; checked against bpy 5.0.1."""

from __future__ import annotations

from typing import Any

#: the bpy versions the workarounds here were checked against (tests/test_compat_blender.py fails when bpy moves)
CHECKED = ((5, 0, 1),)


def sort_faces(bm: Any) -> None:
    """Put a BMesh's faces in one order, whatever order the operators that made them left.

    ``bmesh.ops.create_uvsphere`` lists the same faces in an order that varies from
    process to process (it goes through a hash keyed by memory addresses). Blender
    sums a vertex's normal over its faces in face order, so the sphere's vertex
    normals, and every pixel that shades them, differed in their last bits from one
    process to the next. Sorted by their vertices, the faces come out the same in
    every process.
    """
    bm.verts.index_update()
    for rank, face in enumerate(sorted(bm.faces, key=lambda f: sorted(v.index for v in f.verts))):
        face.index = rank
    bm.faces.sort(key=lambda f: f.index)
    bm.faces.index_update()
