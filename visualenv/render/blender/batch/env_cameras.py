"""Each env's own camera in a batch: :class:`EnvCameras`, the cameras' part of the batch renderer.

One tiles camera (:mod:`tiles_camera`) renders every env from one shared pose, so each env's camera is shown by the
batch's own means. A camera bound to the state moves its copy instead: the anchor of copy k (its instances' place, and
its anchor empty where it has one) is shifted so that the camera lands on the shared pose (:meth:`EnvCameras._follow`).
A camera the state turns (a bound rotation, a look_at, a MuJoCo camera on a moving body, an orbiting distraction) gets
a shader with every env's own rotation: tile k's rays are turned by copy k's camera rotation, while the copies only
translate (:meth:`EnvCameras._aim_rays`). Turning the copies instead would turn them against the shared world, suns
and Cycles' sampling directions (with shared noise every pixel samples the world light in one direction, in world
space: a turned copy got another "shadow" of the world). A camera the state zooms (lens) or scales is refused.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from mathutils import Matrix, Quaternion, Vector

from visualenv.bindables import BINDABLES
from visualenv.render.batch_limits import TURNS, UNFOLLOWED, check_turning, turning_error, world_error
from visualenv.render.blender.batch.copies import Copy
from visualenv.render.blender.batch.distraction_draws import BatchDistractions
from visualenv.render.blender.batch.env_attributes import CAMERA_TURN, EnvAttributes
from visualenv.render.blender.batch.instances import InstancedCopies
from visualenv.render.blender.batch.tiles_camera import TURNING_NAME, rotation_of, tiles_text, unit_columns
from visualenv.render.blender.look.distraction_scene import focus_distance
from visualenv.render.blender.binding_setters import is_world
from visualenv.render.blender.scene.build import with_ancestors
from visualenv.render.blender.scene.mjcf import PoseWriter
from visualenv.render.plan import CameraObject, RenderPlan


class EnvCameras:
    """Which cameras the state moves or turns, each env's pose of a camera, and the copies and rays that show it.

    A mixin of :class:`~visualenv.render.blender.batch.renderer.BatchedBlenderRenderer`, which sets what it reads.
    """

    # the renderer's, set by BlenderRenderer and BatchedBlenderRenderer._setup
    n: int
    plan: RenderPlan
    shader_updates: int
    _objects: dict[str, Any]
    _poses: PoseWriter | None
    _scene: Any
    _layer: Any
    _copies: list[Copy]
    _removed: set[int]
    _instances: InstancedCopies | None
    _table: np.ndarray
    _body_poses: tuple[np.ndarray, np.ndarray]
    _copy_poses: list[tuple[int, Any]] | None
    _distracting: BatchDistractions | None
    _env_values: EnvAttributes
    _turned_headlights: bool
    # the cameras' own, set there too
    _tracked: dict[int, tuple[int, bool]]
    _orbiting: set[int]
    _camera_rows: list[tuple[np.ndarray, np.ndarray]]
    _grid: np.ndarray
    _offsets: np.ndarray
    _carrying: list[tuple[int, Any]]
    _anchors_moved: bool
    _rays: dict[int, dict[str, float]]

    def _tracked_cameras(self) -> dict[int, tuple[int, bool]]:
        """The model's moving cameras: (their index in MuJoCo's camera arrays, whether they turn), by object pointer."""
        physics, poses = self.plan.physics, self._poses
        if physics is None or poses is None:
            return {}
        return {
            camera.as_pointer(): (i, info.turns)
            for i, (info, camera) in enumerate(zip(physics.cameras, poses.cameras))
            if info.moves and self._objects.get(info.name) == camera
        }

    def _refuse_turning_cameras(self) -> None:
        """A camera the state turns (or zooms) cannot share one pose with its copies; a bound world cannot be shared."""
        plan = self.plan
        for view in plan.views.values():
            why = self._turning(view.camera)
            if why:
                raise turning_error(plan, view.camera, why)
            if self._turns(view.camera):
                check_turning(plan, view.camera, view.color, self.n)
        for name in dict.fromkeys(target.object for target in plan.bindings):
            if is_world(name, self._objects):
                raise world_error(plan, name)

    def _turning(self, camera_name: str) -> str | None:
        """What zooms or scales this camera with the state ("its scale binding on 'Rig'"), or None if nothing does."""
        plan, objects = self.plan, self._objects
        bound: dict[str, set[str]] = {}
        for target in plan.bindings:
            bound.setdefault(target.object, set()).add(target.property)
        names = {obj.as_pointer(): name for name, obj in objects.items()}
        camera = objects[camera_name]
        for obj in with_ancestors(camera):
            props = bound.get(names.get(obj.as_pointer(), ""), set())
            turning = (props & set(UNFOLLOWED)) | (props & {"lens"} if obj == camera else set())
            if turning or obj.constraints:
                what = f"its {', '.join(sorted(turning))} binding" if turning else "a constraint"
                return f"{what} on '{names.get(obj.as_pointer(), obj.name)}'"
        return None

    def _turns(self, camera_name: str) -> bool:
        """Whether the state turns this camera (a rotation or look_at bound on it or an ancestor, or it is aimed and
        moves; a model camera that hangs on a moving body or aims at one): its tiles shader then turns each env's rays
        (:meth:`_aim_rays`)."""
        objects = self._objects
        if (
            self._tracked.get(objects[camera_name].as_pointer(), (0, False))[1]
            or objects[camera_name].as_pointer() in self._orbiting
        ):
            return True  # a model camera on a moving body, or aimed at one; an observation camera a distraction orbits
        names = {obj.as_pointer(): name for name, obj in objects.items()}
        spec = self.plan.scene.objects.get(camera_name)
        aimed = isinstance(spec, CameraObject) and spec.look_at is not None
        props = {
            t.property
            for t in self.plan.bindings
            if t.object in {names.get(o.as_pointer(), "") for o in with_ancestors(objects[camera_name])}
        }
        return bool(props & set(TURNS) or (aimed and props & {"location"}))

    def _camera_moves(self, camera: Any) -> bool:
        """Whether a binding moves the camera (or an ancestor), or it is a model camera that moves: then the copies'
        anchors follow it every step."""
        if camera.as_pointer() in self._tracked or camera.as_pointer() in self._orbiting:
            return True
        chain = {o.as_pointer() for o in with_ancestors(camera)}
        carriers = {name for name, obj in self._objects.items() if obj.as_pointer() in chain}
        return any(t.object in carriers and BINDABLES[t.property].moves for t in self.plan.bindings)

    def _place_copies(self, reference: Vector, moving_camera: Any) -> None:
        """Copies where the custom camera expects them: shifted to follow a moving camera, else on their grid places."""
        if moving_camera is not None:
            self._follow(moving_camera, reference)
        elif self._anchors_moved:
            self._offsets[:] = self._grid
            for k, anchor in self._carrying:
                anchor.location = self._grid[k]
            self._anchors_moved = False

    def _shader_text(self, source: Any) -> Any:
        """The tiles shader of a camera: with every env's own ray rotation if the state turns it."""
        name = next(n for n, o in self._objects.items() if o == source)
        return tiles_text(self.n if self._turns(name) else 0)

    def _aim_rays(self, tiles: Any, source: Any) -> None:
        """Turn each env's rays by its camera's rotation relative to the tiles camera (a turning camera only).

        The copies only translate (:meth:`_follow`), so the shared world, suns and Cycles' sampling
        directions stay those of one env: turning the copies instead made the sampled light of the
        world fall in other directions (noise="shared" draws the same directions for every pixel).
        A change of rotations is a shader parameter change: Cycles compiles the shader again.
        """
        if tiles.data.custom_shader is None or not tiles.data.custom_shader.name.startswith(TURNING_NAME):
            return
        # in float64, from the matrices Blender composes from location, rotation and scale (those Cycles renders):
        # rounding here shows as whole rows of a fine floor texture flipping between its checks
        flip = np.diag([1.0, 1.0, -1.0])
        to_camera = flip @ np.linalg.inv(rotation_of(tiles.matrix_basis))
        values, turns = {}, []
        for k, pose in enumerate(self._camera_poses(source)):
            rotation = to_camera @ pose[:3, :3] @ flip
            quat = Matrix(rotation.tolist()).to_quaternion()
            for i in range(4):
                values[f"r{k}_{i}"] = float(quat[i])
            axis, angle = quat.to_axis_angle()
            turns.append(tuple(axis * angle))
        if self._turned_headlights:  # a MuJoCo look's headlight along env k's own camera axis
            self._env_values.write({CAMERA_TURN: np.array(turns)})
        if values != self._rays.get(tiles.as_pointer()):
            params = tiles.data.cycles_custom
            for key, value in values.items():
                params[key] = value
            tiles.data.update_tag()
            self.shader_updates += 1
            self._rays[tiles.as_pointer()] = values

    @staticmethod
    def _camera_pose(copy: Copy, name: str) -> Matrix:
        """The world pose of a copy's camera, up to its anchor's translation (as evaluated under its parents)."""
        camera = copy.objects[name]
        return camera.matrix_basis if camera.parent == copy.anchor else camera.matrix_world

    def _env_pose(self, tiles: Any, pose: Matrix, i: int) -> Matrix:
        """Env i's camera pose at the tiles camera's place (before its grid offset): `pose` turned by env i's rays."""
        values = self._rays.get(tiles.as_pointer())
        if values is None:
            return pose
        flip = Matrix.Diagonal((1.0, 1.0, -1.0))
        rotation = Quaternion([values[f"r{i}_{c}"] for c in range(4)]).to_matrix()
        turned = pose.to_3x3().normalized() @ flip @ rotation @ flip
        return Matrix.Translation(pose.translation) @ turned.to_4x4()

    def _follow(self, camera: Any, reference: Vector) -> None:
        """Shift each copy so that its (translated) camera stands where the custom camera expects it."""
        cameras = self._camera_poses(camera)[:, :3, 3].astype(np.float32)
        # in float32, as mathutils' vectors add
        places = (self._grid + np.array(tuple(reference), dtype=np.float32)) - cameras
        for k, anchor in self._carrying:
            anchor.location = places[k]
        self._offsets[:] = places
        self._anchors_moved = True

    def _camera_poses(self, camera: Any) -> np.ndarray:
        """Each env's pose of `camera` in its own copy (relative to its anchor), ``(N, 4, 4)`` float64: a model camera's
        is its env's cam_xpos and cam_xmat (as one env's camera takes them: mjcf.PoseWriter); an observation camera
        that a distraction orbits, orbited as the env's own (:class:`BatchDistractions`)."""
        tracked = self._tracked.get(camera.as_pointer())
        if tracked is not None and self._camera_rows:
            places = np.array([r[0][tracked[0]] for r in self._camera_rows], dtype=np.float64)
            rotations = np.array(
                [np.asarray(r[1][tracked[0]], dtype=np.float64).reshape(3, 3) for r in self._camera_rows]
            )
        elif tracked is not None:  # no poses handed yet: where the model puts it at qpos0
            places = np.tile(tuple(camera.matrix_basis.translation), (self.n, 1))
            rotations = np.tile(rotation_of(camera.matrix_world), (self.n, 1, 1))
        elif camera.as_pointer() in self._removed and self._instances is not None:  # computed: no copies to read
            poses_given = self._body_poses if self._copy_poses is not None else None
            worlds = self._instances.local_matrices(camera, self._table, poses_given).astype(np.float64)
            places, rotations = worlds[:, :3, 3], unit_columns(worlds[:, :3, :3])
        else:
            name = next(n for n, o in self._objects.items() if o == camera)
            on_anchor = camera.parent == self._copies[0].anchor  # its location is its place in the copy
            if not on_anchor:
                self._layer.update()  # the camera's place depends on its parents: evaluate them (once for all copies)
            places = np.array(
                [
                    tuple(
                        copy.objects[name].location
                        if on_anchor
                        else (copy.anchor.matrix_world.inverted() @ copy.objects[name].matrix_world).translation
                    )
                    for copy in self._copies
                ],
                dtype=np.float64,
            )
            rotations = np.array([rotation_of(self._camera_pose(copy, name)) for copy in self._copies])
        poses = np.zeros((self.n, 4, 4))
        poses[:, :3, :3], poses[:, :3, 3], poses[:, 3, 3] = rotations, places, 1.0
        if camera.as_pointer() not in self._orbiting:
            return poses
        assert self._distracting is not None
        return np.array(
            self._distracting.orbited(
                camera.as_pointer(),
                poses,
                lambda k: focus_distance(
                    self._scene,
                    Matrix(poses[k].tolist()),
                    camera.data.clip_start,
                    Vector(self._offsets[k]),
                    self._posed_for_cast,
                ),
            )
        )

    def _posed_for_cast(self) -> None:
        """Every env's instances posed, as the next render draws them, for a ray cast (the renderer's)."""
        raise NotImplementedError
