"""Many envs in one Blender scene, rendered by one Cycles call per camera: :class:`BatchedBlenderRenderer`.

The scene is built once, as for one env. Env k's copy of it stands on a grid
whose spacing is larger than the cameras' clip distance plus the scene's size,
so no camera reaches another copy. Meshes and empties whose world matrices
numpy can compute (moving or not) are drawn as Geometry Nodes instances, one
instancer per mesh posed for every env from the binding values (and a MuJoCo
model's body poses) in one call (:mod:`instances`); cameras are not copied
unless aimed (a moving camera's pose per env is computed the same way). What
remains (lights, aimed cameras, objects with constraints,
animation or a bound texture, and their parents) is copied N - 1 times as linked
duplicates, copy k under an anchor empty at k's grid place, its bindings written
copy by copy (:mod:`copies`, which also gives a sun bound to the state one sun a
copy, light-linked to its copy: at most 63 envs; point, spot and area lights are
linked likewise up to 63 envs, which keeps every object of such a scene a copy).

One render makes one image of ``cols x rows`` tiles, tile k being env k's
observation, through a Cycles custom camera at the observation camera's pose
(:mod:`tiles_camera`). A camera the state moves moves its copy instead, and a
camera it turns turns each env's rays (:mod:`env_cameras`); one it zooms (lens)
or scales is refused.

This module schedules the render calls: an image holds at most
:data:`~batch_calls.MAX_IMAGE_PIXELS` (a larger batch is rendered in parts of whole rows of
copies), and envs an autoreset just reset are rendered alone where that costs
less than every tile again (:func:`~batch_calls.alone_limit`). It extends
:class:`BlenderRenderer` through its construction and render hooks
(``_setup``, ``_setter``, ``_render``).
"""

from __future__ import annotations

import os
import time
from dataclasses import replace
from typing import Any, Sequence

import numpy as np
from mathutils import Matrix, Vector

from visualenv.errors import RenderError
from visualenv.render.base import DEFAULT_OPTIONS, RenderPlan, RendererOptions
from visualenv.render.distractions import Distraction
from visualenv.render.frames import Frames, Poses
from visualenv.render.batch_limits import (
    MAX_LINKED_ENVS,
    MAX_TURNING_ENVS,
    engine_message,
    sun_error,
    sun_world_error,
)
from visualenv.render.blender.batch.calls import MAX_IMAGE_SIDE, alone_limit, envs_per_call
from visualenv.render.blender.batch.distraction_draws import BatchDistractions
from visualenv.render.blender.batch.env_cameras import EnvCameras
from visualenv.render.blender.batch.env_attributes import CAMERA_TURN, EnvAttributes, read_per_env, turn_to_env_cameras
from visualenv.render.blender.batch.instances import InstancedCopies, removable
from visualenv.render.blender.batch.copies import (
    Copy,
    aim_copy,
    copy_spacing,
    grid_offset,
    hidden,
    is_sun,
    linked_local_lights,
    make_copy,
    one_colour,
    warn_shared_lights,
)
from visualenv.render.blender.renderer import BlenderRenderer, View, write_bindings
from visualenv.render.blender.batch.tiles_camera import (
    grid_shape,
    make_tiles_camera,
    tile,
)
from visualenv.render.blender.scene.build import BuiltScene


class BatchedBlenderRenderer(EnvCameras, BlenderRenderer):
    """Renders `num_envs` copies of a plan's scene in one Blender scene, one Cycles call per observation camera.

    ``render(frames)`` takes :class:`~visualenv.render.frames.Frames` of N envs (their values one
    tuple per env, or an ``(N, values)`` array, as :meth:`BatchedVectorEnv.binding_table` gives) and
    returns every env's tile, ``(N, H, W, C)`` uint8, or a dict of those for several cameras.
    """

    #: the Camera Data node measures depth from the custom camera's pose (copy 0's); a ray starts at its own copy's camera
    DEPTH_ALONG_RAY = True

    def __init__(
        self, plan: RenderPlan, options: RendererOptions = DEFAULT_OPTIONS, *, num_envs: int = 1, instanced: bool = True
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer of at least 1, got {num_envs!r}")
        #: whether moving meshes may be drawn as instances (:mod:`instances`); False copies every object (the path before)
        self.instanced = instanced
        engine = plan.settings.engine
        if engine != "cycles":
            raise ValueError(engine_message(engine))
        self.n = num_envs
        # Cycles draws each pixel's random numbers from its place in the image, so tile k would carry other
        # noise than env k alone; with shared noise a tile equals the env's own render (noise="shared")
        plan = replace(plan, settings=replace(plan.settings, noise="shared"))
        super().__init__(plan, options)

    # -- construction -------------------------------------------------------------------------------

    def _setup(self, built: BuiltScene, threads: int) -> None:
        # Cycles' render threads (0: every core this process may use)
        self._threads = threads or len(os.sched_getaffinity(0))
        # objects drawn as instances rather than copied (none while the base class compiles)
        self._removed: set[int] = set()
        super()._setup(built, threads)
        settings = self.plan.distractions  # drawn per env (batch_distractions), the scene's materials as one env's
        self._distracting = (
            BatchDistractions(settings, built.scene, self.n, self._raw_colors, self._own)
            if settings is not None
            else None
        )
        orbiting = self._distracting is not None and self._distracting.orbiting
        if self._distracting is not None and self._distracting.floor_faded:
            self._see_through = True  # the floor's rays go on through it
        self._orbiting = {self._objects[v.camera].as_pointer() for v in self.plan.views.values()} if orbiting else set()
        #: the MuJoCo model's cameras that move (tracking a body or hanging on one), by object pointer: (their row of
        #: cam_xpos and cam_xmat, whether they turn); each env's pose is its lane's (:meth:`_pose_envs`)
        self._tracked = self._tracked_cameras()
        self._camera_rows: list[tuple[np.ndarray, np.ndarray]] = []  # each env's cam_xpos and cam_xmat, as last handed
        self._refuse_turning_cameras()
        scene = built.scene
        #: whether a MuJoCo look's headlight is turned to each env's camera (a turning observation camera: env_attributes)
        self._turned_headlights = any(self._turns(v.camera) for v in self.plan.views.values()) and turn_to_env_cameras(
            scene
        )
        self._layer.update()  # matrix_world of every object, read below
        reach = max((self._objects[v.camera].data.clip_end for v in self.plan.views.values()), default=100.0)
        backdrops = self._distracting is not None and self._distracting.backdropped  # each env's within its far clip
        self._spacing = copy_spacing(scene, 2 * reach if backdrops else reach)
        self._cols = self._grid_columns()
        # suns are directional: one serves every copy, unless bound to the state: then each copy has its own, lighting
        # only that copy's objects (Cycles' light linking)
        self._own_suns = {
            built.objects[t.object].as_pointer()
            for t in self.plan.bindings
            if t.object in built.objects and is_sun(built.objects[t.object])
        }
        copied = [o for o in scene.objects if (not is_sun(o) or o.as_pointer() in self._own_suns) and not hidden(o)]
        #: the lights that light only their own copy (light linking): bound suns, and every copied local light where
        #: Cycles can tell the copies apart (:func:`~copies.linked_local_lights`)
        self._own_lights = self._own_suns | linked_local_lights(copied, self.n)
        warn_shared_lights(copied, self.n)
        if self._own_suns and self.n > MAX_LINKED_ENVS:  # a .blend file's sun (the spec's were refused at build)
            name = next(
                t.object for t in self.plan.bindings if t.object in built.objects and is_sun(built.objects[t.object])
            )
            raise sun_error(self.plan, name, self.n)
        # a .blend file's world (the spec's: at build)
        if self._own_suns and self.n > 1 and not one_colour(scene.world):
            name = next(
                t.object for t in self.plan.bindings if t.object in built.objects and is_sun(built.objects[t.object])
            )
            raise sun_world_error(self.plan, name)
        places = {o.as_pointer(): o.matrix_world.copy() for o in copied}  # before copy 0 hangs under its anchor
        self._removed = self._removable(copied)
        # the pose writers of the copies (None: no poses handed yet)
        self._copy_poses: list[tuple[int, Any]] | None = None
        self._body_poses: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty(0))  # every env's xpos and xquat
        self._copies = [
            make_copy(k, built, copied, places, self._offset(k), removed=self._removed, own_lights=self._own_lights)
            for k in range(self.n)
        ]
        for copy in self._copies:
            self._objects, self._last = copy.objects, None
            copy.setters = [s for s in self._compile_bindings() if s[2] is not _instanced]
            copy.aimed, copy.targets = self._aimed, self._targets
        self._objects = built.objects
        # whether any binding is written per copy
        self._per_copy = bool(self._copies[0].setters or self._copies[0].aimed)
        # the copies' grid places
        self._grid = np.array([tuple(self._offset(k)) for k in range(self.n)], dtype=np.float32)
        self._offsets = self._grid.astype(np.float64)  # each copy's anchor, as its instances see it
        self._instances = self._instance(copied)
        #: the anchors that carry an object drawn as itself, by env: only they follow a moving camera (the others
        #: hold nothing, or copy 0's originals that instances draw)
        self._carrying = [
            (k, copy.anchor)
            for k, copy in enumerate(self._copies)
            if copy.anchor is not None
            and any(o.as_pointer() not in self._removed for o in copy.anchor.children_recursive)
        ]
        self._table = np.zeros((self.n, self._instances.size if self._instances is not None else 0))
        self._tiled_views = [self._tiled_view(view) for view in self._views]
        #: what each env's shaders read of their own (its colour shifts, its camera's turn)
        self._env_values = EnvAttributes.of_copies(
            self._copies, [o for o in copied if o.as_pointer() not in self._removed], self._instances
        )
        if self._distracting is not None:  # its backdrop about the place the first camera's rays start from
            self._distracting.attach(self._env_values)
            if self._distracting.backdropped:
                centres = self._grid + np.array(tuple(self._tiled_views[0][1]), dtype=np.float32)
                self._add_backdrop(
                    self._distracting.make_backdrops(
                        self._copies[0].anchor.users_collection[0], centres, self._views[0].camera.data.clip_end
                    )
                )
        self._tiled_view_camera: tuple[View, Any, bool] | None = None  # the view camera's, built at the first view
        # per observation camera: the one-tile camera of _render_alone, built at first use
        self._alone: dict[int, View] = {}
        #: how often a custom camera's shader parameters changed after construction (each makes Cycles compile it again)
        self.shader_updates = 0
        self._anchors_moved = False
        #: per tiles camera of a turning camera: its rotation parameters as last written (:meth:`_aim_rays`)
        self._rays: dict[int, dict[str, float]] = {}

    def _removable(self, copied: list[Any]) -> set[int]:
        """The objects to draw as instances (:func:`instances.removable`): none without instancing, or with a light of each
        copy's own (light linking is per object, and one instancer's instances share it). A MuJoCo body's objects are
        instanced too: the instancers take every env's body poses at once (:meth:`_pose_envs`)."""
        if not self.instanced or self._own_lights:
            return set()
        return removable(
            copied, self.plan.bindings, self._objects, {name for _, name in self._aimed}, self._posed_bodies()
        )

    def _posed_bodies(self) -> dict[int, int]:
        """The MuJoCo body index of each object (by pointer) that takes a moving body's pose."""
        return {} if self._poses is None else {obj.as_pointer(): body for body, obj in self._poses.bodies}

    def _instance(self, copied: list[Any]) -> InstancedCopies | None:
        """The instancers of the removed objects, in copy 0's collection, posed for the first render by :meth:`_write_instances`."""
        removed = [o for o in copied if o.as_pointer() in self._removed]
        if not removed:
            return None
        anchor = self._copies[0].anchor
        cameras = [view.camera for view in self._views] + ([self._view.camera] if self._view is not None else [])
        # anchors that stay put: static meshes realized
        anchored = not any(self._camera_moves(camera) for camera in cameras)
        return InstancedCopies(
            anchor.users_collection[0],
            anchor,
            removed,
            self.plan.bindings,
            self._objects,
            self.n,
            self._posed_bodies(),
            realize_static=anchored,
            env_attributes=read_per_env,
        )

    def _setter(self, name: str, obj: Any, prop: str, targets: dict[str, Any]) -> Any:
        """No setter for an object drawn as instances: its instances are posed from numpy (:meth:`_write_instances`)."""
        if obj.as_pointer() in self._removed:
            return _instanced
        return super()._setter(name, obj, prop, targets)

    def _grid_columns(self) -> int:
        """Columns of the grid of copies: the most square grid, or, for a batch past one image, the columns of one
        image's grid, so that each image shows whole rows of copies (:meth:`_render_rows`)."""
        per_call = min((envs_per_call(self.n, v.width, v.height) for v in self._views), default=self.n)
        return grid_shape(self.n if per_call >= self.n else per_call)[0]

    def _offset(self, k: int) -> Vector:
        return grid_offset(k, self._cols, self._spacing)

    def _tiled_view(self, view: View) -> tuple[View, Any, bool]:
        """The custom camera that renders `view` for every env, and whether its camera moves with the state."""
        name = f"{self._scene.name}-{view.key}-tiles"
        camera = make_tiles_camera(
            self._scene,
            name,
            view.camera,
            self._shader_text(view.camera),
            view.width,
            view.height,
            self._spacing,
            self._cols,
        )
        self._own(camera, camera.data)
        tiled = View(view.key, camera, view.width, view.height, view.color, view.depth_range, view.config)
        return tiled, view.camera.matrix_world.normalized().translation.copy(), self._camera_moves(view.camera)

    # -- rendering ----------------------------------------------------------------------------------

    def render(self, frames: Frames) -> np.ndarray | dict[str, np.ndarray]:
        """Each env's poses, distraction and binding values applied to its copy, every observation camera rendered.

        With ``frames.envs`` (ascending indices) only those envs' tiles are returned, ``(len(envs), H, W, C)``: the
        envs an autoreset just reset, rendered alone where that costs less than all N tiles (:func:`alone_limit`).
        """
        envs, values = frames.envs, frames.values
        self._check_open()
        if len(values) != self.n:
            raise ValueError(f"expected binding values for {self.n} envs, got {len(values)}")
        chosen = None if envs is None else [int(i) for i in envs]
        if chosen is not None and (
            not chosen or any(b <= a for a, b in zip(chosen, chosen[1:])) or not 0 <= chosen[0] <= chosen[-1] < self.n
        ):
            raise ValueError(f"envs must be ascending indices below {self.n}, got {chosen}")
        self._take_envs(frames)
        self._write_copies(values, chosen)
        # else every tile is cheaper
        alone = chosen is not None and len(chosen) < alone_limit(self.n, self.device, self._threads)
        images = {}
        for j, ((view, reference, moving), source) in enumerate(zip(self._tiled_views, self._views)):
            self._place_copies(reference, source.camera if moving else None)
            self._aim_rays(view.camera, source.camera)
            self._write_instances()
            if alone:
                images[view.key] = self._render_alone(j, chosen)  # type: ignore[arg-type]
            else:
                tiles = self._render_tiles(view)
                images[view.key] = tiles if chosen is None else tiles[chosen]
        return next(iter(images.values())) if self.plan.single else images

    def render_view(self, frames: Frames) -> np.ndarray:
        """Every env's high-resolution RGB view, ``(N, H, W, 3)``: the view camera's tiles, in as few calls as fit.

        The view's render settings differ from the observations', so the next observation
        render re-synchronises the whole scene with Cycles: a view costs far more than a step.
        """
        self._check_open()
        if self._view is None:
            raise RenderError(
                "the spec has no camera to render a view with (add an 'observation' or 'render.view.camera')"
            )
        if self._tiled_view_camera is None:
            camera_name = self.plan.view_camera
            why = self._turning(camera_name) if camera_name is not None else None
            if why:
                raise RenderError(
                    f"the view camera '{camera_name}' cannot be batched ({why}): a batch renders "
                    "every env through one custom camera with one lens; record a view with one env (visualenv.make)"
                )
            if camera_name is not None and self._turns(camera_name) and self.n > MAX_TURNING_ENVS:
                raise RenderError(
                    f"the view camera '{camera_name}' turns with the state: a batch's tiles shader turns the rays "
                    f"of at most {MAX_TURNING_ENVS} envs, not {self.n}; record a view with one env (visualenv.make)"
                )
            self._tiled_view_camera = self._tiled_view(self._view)
        if len(frames.values) != self.n:
            raise ValueError(f"expected binding values for {self.n} envs, got {len(frames.values)}")
        self._take_envs(frames)
        self._write_copies(frames.values, None)
        view, reference, moving = self._tiled_view_camera
        self._place_copies(reference, self._view.camera if moving else None)
        self._aim_rays(view.camera, self._view.camera)
        self._write_instances()
        return self._render_tiles(view)

    def _take_envs(self, frames: Frames) -> None:
        """Each env's distraction and MuJoCo poses, where `frames` has them."""
        if frames.distractions is not None:
            self._distract_envs(frames.distractions)
        if frames.poses is not None:
            self._pose_envs(frames.poses)

    def _pose_envs(self, poses: Sequence[Poses]) -> None:
        """Each env's MuJoCo poses (xpos, xquat, cam_xpos, cam_xmat, light_xpos, light_xdir) for its copy of the model.

        The bodies drawn as instances take every env's ``xpos`` and ``xquat`` at once, gathered into two
        ``(N, nbody, ...)`` arrays that the instancers pose from (:meth:`_write_instances`); what stays a copy
        (lights, and bodies that cannot be instanced) is written copy by copy. Cameras that are not copied
        take env 0's poses (a batch renders through its own tiles camera).
        """
        if self._poses is None:
            return
        if self._tracked:
            self._camera_rows = [(p[2], p[3]) for p in poses]
        if self._copy_poses is None:  # the writers depend on the model alone: made at the first call
            nbody = len(poses[0][0])
            self._body_poses = (np.empty((self.n, nbody, 3)), np.empty((self.n, nbody, 4)))
            # copy 0 holds the originals: all but the instanced bodies; another copy: its duplicates (lights, bodies left as copies)
            originals = {obj.as_pointer() for obj in self._copies[0].objects.values()}
            writers = [
                self._poses.for_objects(copy.objects).without(originals if k else self._removed, keep_cameras=not k)
                for k, copy in enumerate(self._copies)
            ]
            self._copy_poses = [(k, writer) for k, writer in enumerate(writers) if not writer.empty]
        if self._instances is not None and self._instances.posed:
            for parts, out in zip(([p[0] for p in poses], [p[1] for p in poses]), self._body_poses):  # one C loop each
                np.concatenate(parts, out=out.reshape(-1, out.shape[2]))
        for k, writer in self._copy_poses:
            writer.write(*poses[k])

    def _distract_envs(self, distractions: Sequence[Distraction]) -> None:
        """Each env's distraction in the next renders, drawn as the env alone draws it (:mod:`batch_distractions`)."""
        if self._distracting is None:
            raise RenderError("this batch draws no distractions: its plan had none when it was built")
        if len(distractions) != self.n:
            raise ValueError(f"expected a distraction for each of {self.n} envs, got {len(distractions)}")
        self._distracting.current = list(distractions)

    def _write_copies(self, values: Sequence[Sequence[Any]] | np.ndarray, envs: Sequence[int] | None) -> None:
        """Each env's binding values into its copy (the bindings of copied objects, env by env; `envs` only, when given)
        and into the table its instances are posed from (:meth:`_write_instances`, every env: the others are not shown)."""
        start = time.perf_counter()
        if self._per_copy:
            rows = values.tolist() if isinstance(values, np.ndarray) else values
            for i in range(self.n) if envs is None else envs:
                self._apply_copy(self._copies[i], tuple(rows[i]))
        if self._instances is not None:
            self._table = np.asarray(values, dtype=np.float64).reshape(self.n, self._instances.size)
        if self._distracting is not None:
            self._distracting.draw()
        if self.profile is not None:
            self.profile.add("write", time.perf_counter() - start)

    def _write_instances(self) -> None:
        """Pose every env's instances from the last binding table, at their copies' anchors (moved by :meth:`_place_copies`)."""
        if self._instances is not None:
            start = time.perf_counter()
            self._instances.write(
                self._table, self._offsets, self._body_poses if self._copy_poses is not None else None
            )
            if self.profile is not None:
                self.profile.add("write", time.perf_counter() - start)

    def _apply_copy(self, copy: Copy, values: tuple) -> None:
        if values != copy.last:
            write_bindings(values, copy.last, self._size, copy.setters, [], copy.targets)
            aim_copy(copy)
            copy.last = values

    def _render_tiles(self, view: View) -> np.ndarray:
        """All envs' tiles of one camera: one render call per image of at most MAX_IMAGE_PIXELS.

        A batch past one image is rendered in parts of whole rows of the grid of copies, each
        part by the same camera translated by its rows: moving a camera is a transform update,
        while changing which envs its shader shows makes Cycles compile it again
        (results/benchmarks/batched-split-images.md). A camera whose row of tiles does not fit
        one image (a large view) changes its parameters per part instead.
        """
        per_call = envs_per_call(self.n, view.width, view.height)
        rows = per_call // self._cols
        turned = view.camera.as_pointer() in self._rays  # its rotations are indexed by env: shown by parameters (first)
        if (
            per_call < self.n
            and rows >= 1
            and max(self._cols * view.width, rows * view.height) <= MAX_IMAGE_SIDE
            and not turned
        ):
            return self._render_rows(view, rows)
        parts = []
        for first in range(0, self.n, per_call):
            count = min(per_call, self.n - first)
            cols, rows = grid_shape(count)
            self._set_shown(view.camera, first, count, cols)
            big = View(
                view.key, view.camera, cols * view.width, rows * view.height, view.color, view.depth_range, view.config
            )
            parts.append(tile(self._render(big), count, view.height, view.width))
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def _render_rows(self, view: View, rows: int) -> np.ndarray:
        """The tiles in parts of `rows` rows of copies: one camera showing the first part, moved down the grid for the others."""
        count = rows * self._cols
        self._set_shown(view.camera, 0, count, self._cols)
        base = view.camera.matrix_world.copy()
        big = View(
            view.key,
            view.camera,
            self._cols * view.width,
            rows * view.height,
            view.color,
            view.depth_range,
            view.config,
        )
        parts = []
        try:
            for p, first in enumerate(range(0, self.n, count)):
                if p:
                    view.camera.matrix_world = Matrix.Translation((0.0, p * rows * self._spacing, 0.0)) @ base
                parts.append(tile(self._render(big), min(count, self.n - first), view.height, view.width))
        finally:
            view.camera.matrix_world = base
        return np.concatenate(parts)

    def _set_shown(self, camera: Any, first: int, count: int, cols: int) -> None:
        """Which envs the tiles camera shows, and in how many columns (a change makes Cycles compile its shader again)."""
        params = camera.data.cycles_custom
        if (params["first"], params["count"], params["cols"]) != (first, count, cols):
            params["first"], params["count"], params["cols"] = first, count, cols
            camera.data.update_tag()  # an ID property change alone does not tell Cycles' persistent data to sync
            self.shader_updates += 1

    def _render_alone(self, j: int, envs: Sequence[int]) -> np.ndarray:
        """The tiles of `envs` through observation camera j, one env-sized render each.

        A second custom camera, fixed at one tile of env 0, is moved onto each env's
        place: moving it is a transform update, while changing the tiles camera's
        parameters (which envs it shows) recompiles its shader.
        """
        view, _, _ = self._tiled_views[j]
        if j not in self._alone:
            alone, _, _ = self._tiled_view(self._views[j])
            params = alone.camera.data.cycles_custom
            params["first"], params["count"], params["cols"], params["grid"] = 0, 1, 1, 1
            alone.camera.data.update_tag()
            self.shader_updates += 1
            self._alone[j] = alone
        alone = self._alone[j]
        if self._turned_headlights:  # the one-tile camera stands at each env's own pose: no turn
            self._env_values.write({CAMERA_TURN: np.zeros((self.n, 3))})
        pose = view.camera.matrix_world.copy()
        images = []
        for i in envs:
            alone.camera.matrix_world = Matrix.Translation(self._offset(i)) @ self._env_pose(view.camera, pose, i)
            images.append(tile(self._render(alone), 1, view.height, view.width))
        return np.concatenate(images)

    def _posed_for_cast(self) -> None:
        """Every env's instances posed, as the next render draws them, for a ray cast."""
        self._write_instances()
        self._layer.update()

    def close(self) -> None:
        self._copies = []
        self._instances = None
        super().close()


def _instanced(values: tuple) -> None:
    """The setter of a binding on an object drawn as instances: nothing to write per copy (dropped from the copies' setters)."""


def batch_renderer(
    plan: RenderPlan, options: RendererOptions = DEFAULT_OPTIONS, *, num_envs: int = 1
) -> BlenderRenderer:
    """The renderer of a batch of `num_envs` envs. A batch of one is drawn by one env's renderer
    (:class:`BlenderRenderer`: its frames are the env's own, at one env's cost, without instancers or a tiles camera);
    a larger one by a :class:`BatchedBlenderRenderer`, which also refuses what no batch renders."""
    if type(num_envs) is int and num_envs == 1 and plan.settings.engine == "cycles":
        return BlenderRenderer(plan, options)
    return BatchedBlenderRenderer(plan, options, num_envs=num_envs)
