"""A batch's objects drawn as Geometry Nodes instances posed from numpy: the same pixels as copied objects, no copies per env."""

from __future__ import annotations

import numpy as np
import pytest

from visualenv.env.batch import BatchedVectorEnv
from visualenv.render.base import RendererOptions
from visualenv.spec import load_spec_text
from visualenv.render.frames import Frames

pytestmark = pytest.mark.blender

pytest.importorskip("bpy")

#: parents three deep (an empty, a mesh, a mesh), bound location, rotation, scale, visibility (of an empty: everything
#: under it) and colour (of a mesh, and of an empty: its meshes'); a static floor; a sun (a point, spot or area light
#: would be each copy's own, light-linked, and keep every object a copy: tests/env/test_batch_scale.py)
SCENE = """\
id: Instances-v0
scene:
  world: {color: [0.2, 0.2, 0.25], strength: 1.0}
  objects:
    Floor: {primitive: plane, size: 8, material: {color: [0.3, 0.3, 0.3]}}
    Rig:   {empty: true, location: [0, 0, 0.5]}
    Body:  {primitive: cube, size: [1.0, 0.6, 0.4], parent: Rig, material: {color: [0.8, 0.2, 0.2]}}
    Arm:   {primitive: cylinder, radius: 0.12, depth: 1.2, parent: Body, location: [0.3, 0, 0.5], rotation: [0.3, 0, 0], material: {color: [0.2, 0.7, 0.3]}}
    Ball:  {primitive: sphere, radius: 0.35, location: [1.6, 0, 0.35], material: {color: [0.9, 0.9, 0.2]}}
    Group: {empty: true, location: [-1.5, 0, 0]}
    Cone:  {primitive: cone, radius: 0.3, depth: 0.8, parent: Group, material: {color: [1, 1, 1]}}
    Sun:   {light: sun, strength: 2.0, rotation: [0.6, 0.2, 0.4]}
    Camera: {camera: perspective, location: [0, -6, 3], look_at: [0, 0, 0.5], lens: 30}
state:
  x: {init: "uniform(-1, 1)"}
  a: {init: "uniform(-1, 1)"}
actions:
  discrete: [{push: -1}, {push: 1}]
dynamics:
  update: {x: x + 0.2 * push, a: a + 0.4}
actors:
  Rig:  {location: [x, 0, 0.5], visible: "a < 1.2"}
  Body: {rotation: [0, 0, a], scale: [1 + 0.3 * x, 1, 1], color: [0.5 + 0.4 * x, 0.3, 0.6 - 0.3 * x]}
  Arm:  {rotation: [a, 0, 0]}
  Ball: {visible: "x > 0", color: [0.9, 0.5 + 0.4 * a, 0.2]}
  Group: {color: [0.2, 0.3, 0.9 - 0.2 * x]}
observation: {camera: Camera, resolution: [32, 32], color: rgb}
render: {engine: cycles, preset: fast, device: cpu}
reward: 0.0
max_steps: 50
"""


def _renderers(env: BatchedVectorEnv) -> tuple:
    from visualenv.render.blender.batch.renderer import BatchedBlenderRenderer

    options = RendererOptions.parse(None)
    plan = env.program.render_plan().with_options(options)
    return (
        BatchedBlenderRenderer(plan, options, num_envs=env.num_envs, instanced=True),
        BatchedBlenderRenderer(plan, options, num_envs=env.num_envs, instanced=False),
    )


def test_instanced_tiles_equal_copied_tiles():
    """Parents, visibility, scale and colour through instances: every tile equals the copied objects' tile, pixel for
    pixel but for rounding. An instance's colour is read through an Attribute node, a copy's is its material's own
    value: Cycles' two shader programs round apart, by one level in one pixel of 4,096 here once the ball's colour
    passes 1 (with the colour fixed, every step is equal to the bit)."""
    env = BatchedVectorEnv(load_spec_text(SCENE, name="instances.yaml"), 4, render=False)
    env.reset(seed=5)
    instanced, copied = _renderers(env)
    try:
        names = {
            instanced.object(n).as_pointer(): n
            for n in ("Floor", "Rig", "Body", "Arm", "Ball", "Group", "Cone", "Sun", "Camera")
        }
        assert {names[p] for p in instanced._removed if p in names} == {
            "Floor",
            "Rig",
            "Body",
            "Arm",
            "Ball",
            "Group",
            "Cone",
            "Camera",
        }
        assert not instanced._per_copy  # no binding is written copy by copy
        assert _instanced(instanced, realized_only=True) == {
            "Floor"
        }  # the one mesh nothing moves, hides or colours: one realized mesh
        tiles, seen = [], set()
        x, a = (env.program.state_names.index(name) for name in ("x", "a"))
        for step in range(4):
            table = env.binding_table()
            ours, theirs = instanced.render(Frames(table)), copied.render(Frames(table))
            difference = np.abs(ours.astype(int) - theirs.astype(int))
            assert difference.max() <= 1 and (difference > 0).sum() <= 2, (
                f"step {step}: {(ours != theirs).any(axis=-1).sum()} pixels differ"
            )
            tiles.append(ours)
            seen |= {("ball", bool(v > 0)) for v in env._state[x]} | {("rig", bool(v < 1.2)) for v in env._state[a]}
            env.step(np.array([step % 2] * 4))
        # a test that cannot fail otherwise: the ball and the rig are hidden in some renders and shown in others, and tiles differ
        assert seen == {("ball", True), ("ball", False), ("rig", True), ("rig", False)}, seen
        assert not np.array_equal(tiles[0][0], tiles[0][1]) and not np.array_equal(tiles[0][0], tiles[1][0])
    finally:
        instanced.close()
        copied.close()
        env.close()


def _instanced(renderer, realized_only: bool = False) -> set[str]:
    """The names of the meshes the batch draws through instancers (only those realized into one mesh, if asked)."""
    return {
        inst.mesh.name.removesuffix("-instances")
        for inst in renderer._instances._instancers
        if inst.realized or not realized_only
    }


def test_static_meshes_are_realized_only_where_pixels_stay_the_same():
    """A static mesh is realized unless its material reads its placement (a procedural texture in object coordinates:
    realized, 23 pixels of this scene differ) or a moving camera moves the copies' anchors: then the static meshes
    that a merged mesh draws alike are one mesh in the anchor's space, one instance per env (a static group). Either
    way every tile equals the copied objects' tile."""
    scene = SCENE.replace(
        "    Sun:",
        "    Tiles: {primitive: cube, size: 0.6, location: [-2.4, 1, 0.3], material: {color: [0.9, 0.9, 0.9], "
        "texture: {type: checker, scale: 3}}}\n"
        "    Post: {primitive: cylinder, radius: 0.15, depth: 1.5, location: [2.4, 1.2, 0.75], rotation: [0, 0.3, 0], "
        "scale: [1, 1.5, 1], material: {color: [0.1, 0.4, 0.9]}}\n    Sun:",
    )
    follow = scene.replace("  Group: {color:", "  Camera: {location: [0.5 * x, -6, 3]}\n  Group: {color:")
    for text, realized, groups in ((scene, {"Floor", "Post"}, []), (follow, set(), [["Floor", "Post"]])):
        env = BatchedVectorEnv(load_spec_text(text, name="instances.yaml"), 3, render=False)
        env.reset(seed=2)
        instanced, copied = _renderers(env)
        try:
            assert _instanced(instanced, realized_only=True) == realized
            assert "Tiles" in _instanced(instanced)
            assert sorted(sorted(group) for group in instanced._instances.groups) == groups
            for step in range(2):
                table = env.binding_table()
                ours, theirs = instanced.render(Frames(table)), copied.render(Frames(table))
                assert np.array_equal(ours, theirs), f"step {step}: {(ours != theirs).any(axis=-1).sum()} pixels differ"
                env.step(np.array([1, 0, 1]))
        finally:
            instanced.close()
            copied.close()
            env.close()


@pytest.mark.parametrize(
    "spec, realized, groups, instancers",
    [
        ("visual_cartpole.yaml", {"Track"}, [], 3),  # the moving cart and pole stay instances
        # Goalie's camera follows the goalie: computed, not copied; its eight plain static meshes are one static group (the
        # field's texture reads its object coordinates: its own instancer)
        ("goalie.yaml", set(), [["Column" + str(i) for i in range(1, 8)] + ["GoalLine"]], 3),
    ],
)
def test_a_batch_of_instances_adds_no_objects_per_env(spec, realized, groups, instancers):
    """Every object becomes an instance, and a moving camera is posed from numpy: the scene holds as many objects for
    6 envs as for 2, and no binding is written per env."""
    from pathlib import Path

    from visualenv.spec.loader import load_spec

    loaded = load_spec(Path(__file__).parents[2] / "specs" / spec)
    counts = {}
    for n in (2, 6):
        env = BatchedVectorEnv(loaded, n)
        renderer = env.renderer  # built, not rendered
        counts[n] = len(renderer.scene.objects)
        assert not renderer._per_copy and all(copy.anchor is None for copy in renderer._copies[1:])
        assert _instanced(renderer, realized_only=True) == realized
        assert [sorted(group) for group in renderer._instances.groups] == groups
        assert len(renderer._instances._instancers) == instancers  # one instance each per env, or one realized mesh
        env.close()
    assert counts[2] == counts[6], counts


def test_a_computed_camera_that_turns_or_hangs_on_a_moving_parent_renders_each_envs_own_view():
    """Goalie's camera turned by a bound rotation, and hung on an empty whose location is bound: posed from numpy (no
    camera per env), each tile agrees with the env's own render (noise='shared') on >= 98 % of pixels within 8 levels."""
    from pathlib import Path

    from tests.env.test_batch import after_steps, agreement

    goalie = (Path(__file__).parents[2] / "specs" / "goalie.yaml").read_text()
    turning = goalie.replace(
        "  Camera: {location: [gx, -1, 1.6]}", "  Camera: {location: [gx, -1, 1.6], rotation: [1.05, 0, 0.04 * gx]}"
    )
    hung = goalie.replace("  Camera: {location: [gx, -1, 1.6]}", "  Rig: {location: [gx, 0, 0]}").replace(
        "    Camera: {camera: perspective, lens: 24, location: [0, -1, 1.6],",
        "    Rig: {empty: true}\n    Camera: {camera: perspective, lens: 24, location: [0, -1, 1.6], parent: Rig,",
    )
    assert turning != goalie and "parent: Rig" in hung
    for text in (turning, hung):
        loaded = load_spec_text(text, name="goalie.yaml")
        env = BatchedVectorEnv(loaded, 3)
        assert env.renderer.object("Camera").as_pointer() in env.renderer._removed
        assert all(copy.anchor is None for copy in env.renderer._copies[1:])
        env.close()
        obs, owns = after_steps(loaded, seed=2, actions=[0, 1, 1], steps=4)
        assert all(agreement(obs[i], owns[i]) >= 0.98 for i in range(3)), [agreement(obs[i], owns[i]) for i in range(3)]
        assert agreement(obs[0], obs[1]) < 0.98  # the goalies, and so the views, differ
