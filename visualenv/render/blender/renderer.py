"""The Blender (bpy) renderer: a scene per renderer, bindings applied in place, cameras rendered to numpy."""

from __future__ import annotations

import contextlib
import itertools
import time
from dataclasses import dataclass, replace
from typing import Any, Sequence

import bpy
import numpy as np
from mathutils import Vector

from visualenv.compat.blender import release_render_result
from visualenv.errors import Diagnostic, RenderError, SpecError, did_you_mean, in_file_order
from visualenv.render.pixels import first_channel, read_bmp, to_grayscale
from visualenv.render.base import DEFAULT_OPTIONS, RenderPlan, Renderer, RendererOptions
from visualenv.render.distractions import Distraction
from visualenv.render.frames import Frames
from visualenv.render.blender.runtime import settings as cfg
from visualenv.render.blender.scene import user_file
from visualenv.render.blender.binding_setters import BindingSetters, is_world, write_bindings
from visualenv.render.blender.look.materials import depth_material, depth_world, see_through, world_writer
from visualenv.render.blender.runtime import scene_turns
from visualenv.render.blender.runtime.at_exit import track
from visualenv.render.blender.capture import Capture, install as install_capture
from visualenv.render.blender.look.distraction_scene import DistractionRig
from visualenv.render.blender.readback import OutputFile, quiet_stdout
from visualenv.render.blender.scene.mjcf import build_physics_objects, keep_instanced, show_model_sky
from visualenv.render.blender.look.mujoco import ambient, backdrop, direct_light_only, light_scene, raw_images
from visualenv.render.blender.scene.build import BuiltScene, DataTracker, build_scene, is_alive, remove_ids
from visualenv.render.blender.look.segmentation import (
    SEGMENTATION_CONFIG,
    HiddenLights,
    assign_ids,
    segmentation_material,
    segmentation_world,
)
from visualenv.bindables import camera_problem, type_problem

_instances = itertools.count()


@dataclass(frozen=True)
class View:
    """One camera's render: the camera, its image size, what its pixels hold and the engine settings it renders with."""

    key: str
    camera: Any  # bpy Object
    width: int
    height: int
    color: str  # rgb | grayscale | depth | segmentation
    depth_range: tuple[float, float]
    config: cfg.EngineConfig


class BlenderRenderer(BindingSetters, Renderer):
    """Renders a :class:`RenderPlan` with Blender's ``bpy`` module, in this process.

    The renderer owns one Blender scene (a new one, or the first scene of
    ``scene.file`` appended from the .blend) holding every declared object, so
    several renderers in one process do not interfere. Before each render the
    binding values are written to the objects, skipping those that did not
    change since the last render (:mod:`binding_setters`).

    Observations are ``(H, W, C)`` uint8 arrays, row 0 at the top: ``rgb``
    (C=3, sRGB through Blender's 'Standard' view transform), ``grayscale``
    (C=1, ITU-R BT.601 luma of the sRGB bytes: (299 R + 587 G + 114 B) / 1000)
    and ``depth`` (C=1, the camera's Z depth mapped linearly from
    ``depth_range`` [near, far] to 0..255 and clipped; the background is 255).

    ``plan.settings`` hold the spec's ``render`` section with the Python options' overrides
    (``device``: a missing GPU falls back to the CPU with a one-time warning for ``"gpu"``;
    ``threads``: 0 for all cores); ``options.readback`` says how pixels leave Blender:
    ``"memory"`` (Cycles only: the render result copied in place, see :mod:`capture`),
    ``"file"`` (a BMP in shared memory, any engine) or ``"auto"`` (memory where possible).
    """

    #: depth from the camera ray's length (see :func:`depth_material`) rather than the scene camera's view Z
    DEPTH_ALONG_RAY = False

    def __init__(self, plan: RenderPlan, options: RendererOptions = DEFAULT_OPTIONS) -> None:
        self.plan = plan
        self._closed = True
        settings = plan.settings
        self.obs_config = cfg.make_config(settings, settings.preset)
        self.view_config = cfg.view_config(self.obs_config, settings.view.preset)
        self.device = cfg.resolve_device(settings.device)
        readback = options.readback
        if readback == "memory" and "cycles" not in (self.obs_config.engine, self.view_config.engine):
            raise ValueError("readback 'memory' needs the Cycles engine; use 'file' or 'auto'")
        can_capture = readback != "file" and install_capture()
        if readback == "memory" and not can_capture:
            raise ValueError(
                "readback 'memory' needs Blender's Cycles add-on, which this bpy lacks; use 'file' or 'auto'"
            )
        self._capture = Capture() if can_capture else None
        self._active_capture: Capture | None = None  # the capture armed for the next render (None: read the file)
        cfg.engine_warnings(self.obs_config, self.device)
        self._output = OutputFile()
        tracker = DataTracker()
        try:
            built = build_scene(
                plan.scene, base_dir=plan.base_dir, source=plan.source, prefix=f"visualenv{next(_instances)}"
            )
            self._poses = (
                None
                if plan.physics is None
                else build_physics_objects(
                    plan.physics,
                    built,
                    base_dir=plan.base_dir,
                    source=plan.source,
                    material=plan.scene.default_material,
                    add_light=not plan.physics.lights and not any(o.type == "LIGHT" for o in built.objects.values()),
                )
            )
            if plan.physics is not None and plan.scene.world is None and not plan.scene.file:  # the spec's world wins
                show_model_sky(plan.physics, built.scene.world)
            #: colours written as they are (physics.look: mujoco, as MuJoCo's renderer writes them), not through sRGB
            self._raw_colors = plan.physics is not None and plan.physics.look == "mujoco"
            if self._raw_colors and plan.physics is not None:
                backdrop(built.scene.world)
                # the spec's own objects as geoms
                light_scene(built.scene, plan.physics.headlight, ambient(plan.physics))
                direct_light_only(built.scene)
            self._check_names(built)
            self._setup(built, settings.threads)
            if self._poses is not None:  # after a batch's copies: they share the meshes (no second user needed)
                keep_instanced(built.scene)
        except BaseException:
            remove_ids(tracker.new())
            self._output.close()
            raise
        self._ids = tracker.new()
        self._ids_kept = max(len(self._ids), 64)  # the list's length when removed ones were last let go
        self._closed = False
        track(self)  # closed at exit if the script leaves it open (at_exit.py: a quiet exit)

    # -- construction -------------------------------------------------------------------------------

    def _check_names(self, built: BuiltScene) -> None:
        """Every bound object and every camera must be in the scene, of a type that takes its binding; report all that are not."""
        plan = self.plan
        types = {name: obj.type for name, obj in built.objects.items()}
        problems: list[Diagnostic] = []
        missing: set[str] = set()
        for target in plan.bindings:
            if is_world(target.object, types):
                why = world_writer(built.scene.world, target.property)
                if isinstance(why, str):
                    problems.append(plan.source.diagnostic(("actors", target.object, target.property), why, key=True))
                continue
            if target.object not in types:
                if target.object not in missing:
                    missing.add(target.object)
                    problems.append(
                        plan.source.diagnostic(
                            ("actors", target.object),
                            f"no object '{target.object}' in the scene"
                            + did_you_mean(target.object, types).replace("names:", "objects:"),
                            key=True,
                        )
                    )
                continue
            problem = type_problem(target.property, target.object, types[target.object])
            if problem:
                problems.append(plan.source.diagnostic(("actors", target.object, target.property), problem, key=True))
        for path, camera in plan.cameras:
            problem = camera_problem(camera, types)
            if problem:
                problems.append(plan.source.diagnostic(path, problem))
        if problems:
            raise SpecError(in_file_order(problems))

    def _setup(self, built: BuiltScene, threads: int) -> None:
        plan = self.plan
        scene = self._scene = built.scene
        self._scene_name = scene.name
        self._objects = built.objects
        self._layer = user_file.render_layer(scene)
        self._free_bound_objects(built)
        cfg.configure_scene(scene, device=self.device, threads=threads, noise=plan.settings.noise, raw=self._raw_colors)
        cfg.quiet_emission(scene)
        if self._raw_colors:
            raw_images(scene)
        self._see_through = see_through(scene) or any(t.property == "color" and t.size == 4 for t in plan.bindings)
        r = scene.render
        r.image_settings.file_format = "BMP"
        r.image_settings.color_mode = "RGB"
        r.use_file_extension = False
        r.filepath = self._output.path
        self._views = [
            View(
                key,
                built.objects[v.camera],
                v.resolution[0],
                v.resolution[1],
                v.color,
                (float(v.depth_range[0]), float(v.depth_range[1])),
                cfg.depth_config(self.obs_config)
                if v.color == "depth"
                else SEGMENTATION_CONFIG
                if v.color == "segmentation"
                else self.obs_config,
            )
            for key, v in plan.views.items()
        ]
        #: configs of observation renders: they keep Cycles' persistent data (a view's config renders afresh)
        self._observation_configs = {self.obs_config, *(v.config for v in self._views)}
        view_camera = plan.view_camera
        self._view = None
        if view_camera is not None:
            w, h = plan.settings.view.resolution
            self._view = View("view", built.objects[view_camera], w, h, "rgb", (0.0, 1.0), self.view_config)
        self._overrides: dict[str, tuple[Any, Any]] = {}  # material and world override by render mode
        if any(v.color == "depth" for v in self._views):
            mat, self._set_depth_range, self._set_depth_forward = depth_material(
                f"{scene.name}-depth", lambda d: d, along_ray=self.DEPTH_ALONG_RAY
            )
            self._overrides["depth"] = (mat, depth_world(f"{scene.name}-depth-world", lambda d: d))
        #: segmentation id of each label or unlabelled object name (empty without a segmentation camera)
        self.segmentation_ids: dict[str, int] = {}
        self._lights = HiddenLights(scene)
        if any(v.color == "segmentation" for v in self._views):
            self.segmentation_ids = assign_ids(built, plan)
            self._overrides["segmentation"] = (
                segmentation_material(f"{scene.name}-segmentation", lambda d: d),
                segmentation_world(f"{scene.name}-segmentation-world", lambda d: d),
            )
        # what the scene is set to now (only changes are written)
        self._camera: Any = None
        self._resolution: tuple[int, int] | None = None
        self._config: cfg.EngineConfig | None = None
        self._mode = ""
        #: the distractions' backdrops (:mod:`distractions`): seen in colour renders only
        self._backdrops: list[Any] = []
        self._depth_range: tuple[float, float] | None = None
        self._depth_forward: tuple[float, ...] | None = None
        self._set_mode("color")
        self._setters = self._compile_bindings()
        self._last: tuple | None = None
        self._rig: DistractionRig | None = None  # made by the first distraction drawn
        self._distraction = Distraction()

    def _free_bound_objects(self, built: BuiltScene) -> None:
        """The env's copy of the scene lets the bindings through: what the file animates, constrains
        or simulates on a bound channel is muted, and the collections of bound objects and cameras
        are rendered (:mod:`user_file`)."""
        plan = self.plan
        bound: dict[str, set[str]] = {}
        for target in plan.bindings:
            if not is_world(target.object, built.objects):
                bound.setdefault(target.object, set()).add(target.property)
        for name, properties in bound.items():
            user_file.free_bound_channels(built.objects[name], properties)
        cameras = [built.objects[v.camera] for v in plan.views.values()]
        user_file.include_collections_of(self._layer, [*(built.objects[n] for n in bound), *cameras])
        user_file.stop_simulations(built.scene)

    # -- rendering ----------------------------------------------------------------------------------

    def apply(self, values: Sequence[Any]) -> None:
        """Write the binding values that changed since the last call, then the distraction (where there is one)."""
        values = tuple(values)
        if values != self._last:
            write_bindings(values, self._last, self._size, self._setters, self._aimed, self._targets)
            self._last = values
        if self._rig is not None:
            self._rig.apply(self._distraction)

    def render(self, frames: Frames) -> np.ndarray | dict[str, np.ndarray]:
        """The observation cameras for the one env of `frames`, ``(1, H, W, C)`` (views of the image just read)."""
        self.write(frames)
        if self.plan.single:
            if not self._views:
                raise RenderError("the spec has no observation camera")
            return self._render(self._views[0])[None]
        return {v.key: self._render(v)[None] for v in self._views}

    def render_view(self, frames: Frames) -> np.ndarray:
        """The high-resolution view of the one env of `frames`, ``(1, H, W, 3)``."""
        self._check_open()
        if self._view is None:
            raise RenderError(
                "the spec has no camera to render a view with (add an 'observation' or 'render.view.camera')"
            )
        self.write(frames)
        return self._render(self._view)[None]

    def write(self, frames: Frames) -> None:
        """Pose, distract and bind the scene as the one env of `frames` is, without rendering: what the next render
        call draws (``visualenv bench``'s floor renders it with Blender's call alone). A renderer of one env refuses
        more."""
        self._check_open()
        if len(frames.values) != 1:
            raise ValueError(f"this renderer draws one env, got binding values for {len(frames.values)}")
        start = time.perf_counter()
        if frames.poses is not None and self._poses is not None:
            self._poses.write(*frames.poses[0])
        if frames.distractions is not None:
            self._distract(frames.distractions[0])
        self.apply(frames.values[0])
        if self.profile is not None:
            self.profile.add("write", time.perf_counter() - start, start)

    def _own(self, *datablocks: Any) -> None:
        """Datablocks made after construction (cameras built at first use, a video's frames): removed with the scene at
        close. Those removed since are let go once the list doubles, so that it holds about the live ones."""
        ids = getattr(self, "_ids", None)
        if ids is None:
            return
        ids.extend(datablocks)
        if len(ids) > 2 * self._ids_kept:
            ids[:] = [datablock for datablock in ids if is_alive(datablock)]
            self._ids_kept = max(len(ids), 64)

    def _distract(self, distraction: Distraction) -> None:
        """Draw `distraction` in the next renders: observation cameras moved, colours shifted (:mod:`distractions`)."""
        if self._rig is None:
            tracker = DataTracker()
            self._rig = DistractionRig(
                self._scene,
                [v.camera for v in self._views],
                backdrop=distraction.background > 0 or distraction.color_shift > 0,
                floor_alpha=distraction.floor_alpha,
                videos=distraction.video >= 0,
                raw_colors=self._raw_colors,
                own=self._own,  # the frames' images, removed at close
            )
            if self._rig.floor_faded:  # the floor's rays go on through it: transparent bounces
                self._see_through = True
                self._config = None
            self._ids.extend(tracker.new())
            if self._rig.backdrop is not None:
                self._add_backdrop(self._rig.backdrop)
            children = self._rig.children
            self._views = [replace(v, camera=children[v.camera.name]) for v in self._views]
            if self._view is not None and self._view.camera.name in children:
                self._view = replace(self._view, camera=children[self._view.camera.name])
        self._distraction = distraction

    def _render(self, view: View) -> np.ndarray:
        scene = self._scene
        if self._camera is not view.camera:
            scene.camera = view.camera
            self._camera = view.camera
        if self._resolution != (view.width, view.height):
            scene.render.resolution_x = view.width
            scene.render.resolution_y = view.height
            self._resolution = (view.width, view.height)
        if self._config != view.config:
            cfg.apply_config(scene, view.config, self._config, see_through=self._see_through)
            # Cycles' persistent data remembers a little of other sample counts: the first
            # observation after a view render would differ from the same one before it. So
            # only observation renders keep the session; any other config renders afresh.
            scene.render.use_persistent_data = view.config in self._observation_configs
            self._config = view.config
        depth = view.color == "depth"
        mode = view.color if view.color in self._overrides else "color"
        if mode != self._mode:
            self._set_mode(mode)
        if depth and self._depth_range != view.depth_range:
            self._set_depth_range(*view.depth_range)
            self._depth_range = view.depth_range
        if depth and self.DEPTH_ALONG_RAY:
            forward = tuple((view.camera.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized())
            if forward != self._depth_forward:
                self._set_depth_forward(forward)
                self._depth_forward = forward
        capture = (
            self._capture.arm(view.width, view.height)
            if self._capture is not None and view.config.engine == "cycles"
            else None
        )
        self._active_capture = capture
        profile = self.profile
        if profile is None:
            self.raw_render()
            return self._read_capture(view, capture) if capture is not None else self._read_file(view)
        start = time.perf_counter()
        self.raw_render()
        rendered = time.perf_counter()
        pixels = self._read_capture(view, capture) if capture is not None else self._read_file(view)
        profile.add("render", rendered - start, start)
        profile.add("readback", time.perf_counter() - rendered, rendered)
        return pixels

    def last_linear_pass(self) -> np.ndarray | None:
        """The linear Combined pass (H, W, RGBA float32, top row first) the last Cycles image was read from; None where
        pixels leave Blender through a file. Renders of one state compare bit for bit here, where 8-bit levels hide most bits."""
        if self._active_capture is None:
            return None
        return self._active_capture.linear()

    def read_again(self) -> np.ndarray:
        """The first observation camera's pixels converted again from the last render's pass, with no render: what a
        step's readback costs alone (``benchmarks/step_gap.py``). Needs an in-memory readback (Cycles). ``(H, W, C)``
        as the pass holds it: one env's frame, or a batch's whole image of tiles (one call reads them all)."""
        self._check_open()
        if self._active_capture is None or not self._views:
            raise RenderError("no in-memory render to read again: render an observation with Cycles first")
        return self._read_capture(self._views[0], self._active_capture)

    def _read_capture(self, view: View, capture: Capture) -> np.ndarray:
        if view.color in ("depth", "segmentation"):
            return capture.raw()
        return capture.rgb(raw=self._raw_colors) if view.color == "rgb" else capture.grayscale(raw=self._raw_colors)

    def _read_file(self, view: View) -> np.ndarray:
        rgb = read_bmp(self._output.path)
        if view.color in ("depth", "segmentation"):
            return first_channel(rgb)
        return rgb if view.color == "rgb" else to_grayscale(rgb)

    def raw_render(self) -> None:
        """Blender's render call, with the scene as it is; the pixels wait in the capture buffer or the file."""
        scene_turns.rendered(self._scene_name)
        if self._active_capture is not None:
            with self._active_capture:
                bpy.ops.render.render(scene=self._scene_name)
        else:
            with quiet_stdout():  # Blender prints "Saved: <file>" for every written frame
                bpy.ops.render.render(write_still=True, scene=self._scene_name)

    def _set_mode(self, mode: str) -> None:
        """'color', or 'depth' / 'segmentation': their material and world overrides, values written raw (lights hidden from the camera for ids)."""
        layer = self._layer
        override = self._overrides.get(mode)
        layer.material_override = override[0] if override else None
        layer.world_override = override[1] if override else None
        cfg.set_color_management(self._scene, raw=override is not None or self._raw_colors)
        if mode == "segmentation":
            self._lights.hide()
        elif self._mode == "segmentation":
            self._lights.show()
        for holder in self._backdrops:
            holder.hide_render = mode != "color"
        self._mode = mode

    def _add_backdrop(self, holder: Any) -> None:
        """A distraction's backdrops, shown in colour renders only; the rays that pass through them need transparent bounces."""
        holder.hide_render = self._mode != "color"
        self._backdrops.append(holder)
        self._see_through = True
        self._config = None  # the bounces written again at the next render

    # -- access and lifecycle -----------------------------------------------------------------------

    @property
    def scene(self) -> Any:
        """The Blender scene this renderer owns."""
        self._check_open()
        return self._scene

    def object(self, name: str) -> Any:
        """The Blender object a spec (or .blend) name refers to."""
        self._check_open()
        return self._objects[name]

    def _check_open(self) -> None:
        if self._closed:
            raise RenderError("the renderer is closed")

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._setters = []
        self._objects = {}
        self._camera = self._view = None
        self._overrides = {}
        self._views = []
        scene_ids, self._ids = self._ids, []
        with contextlib.suppress(ReferenceError, AttributeError, RuntimeError), quiet_stdout():
            # Frees the render engine Cycles keeps for this scene and the last frame Blender
            # keeps for its name, which would otherwise outlive the scene.
            release_render_result(self._scene)
        self._scene = None
        remove_ids(scene_ids)
        self._output.close()
        if self._capture is not None:
            self._capture.close()
