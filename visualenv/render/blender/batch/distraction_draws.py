"""Each env's own distraction in one batch render: :class:`BatchDistractions`.

Env k of a batch draws what env k alone draws (docs/distractions.md), by the batch's own means:

* **camera**: env k's observation camera orbits as the env's own child camera does
  (:func:`~visualenv.render.blender.look.distraction_scene.orbit` about the point measured at env k's first render), and the batch
  follows it as it follows a camera that moves and turns (:mod:`batched`): env k's copy is moved so that its orbited
  camera stands where the tiles camera looks from, and env k's rays are turned by its orbited rotation. A change of any
  env's orbit makes Cycles compile the tiles shader again, as for a camera the state turns;
* **colours**: every material adds a per-env attribute to its colour
  (:func:`~visualenv.render.blender.look.distraction_scene.shift_by_attribute`), which each env's instances and copied objects
  hold (:class:`~visualenv.render.blender.batch.env_attributes.EnvAttributes`). So no static mesh is realized into one mesh
  of every env (its envs would read one shift);
* **floor**: a MuJoCo model's floor takes the settings' alpha, one material for every env, as each env's own
  (:func:`~visualenv.render.blender.look.distraction_scene.fade_floor`);
* **sky and background**: envs share one world, which cannot tell them apart; each env has its own backdrop
  (:func:`~visualenv.render.blender.look.distraction_scene.make_backdrops`, as one env has), an instance about its ray origin
  whose attributes are its numbers. The copies stand twice the cameras' far clip apart, so that no env's backdrop
  reaches another's. With the suite's videos, each env's frame is its tile of one image
  (:class:`~visualenv.render.blender.look.video_backdrop.VideoAtlas`).

Numbers are written when an env's distraction changes: at its resets, and every step when dynamic.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from visualenv.render.blender.look.distraction_scene import (
    distracted_materials,
    fade_floor,
    make_backdrops,
    orbit,
    shift_by_attribute,
    write_backdrops,
)
from visualenv.render.blender.batch.env_attributes import EnvAttributes, shift_name
from visualenv.render.distractions import Distraction, color_shifts, world_up
from visualenv.render.blender.look.video_backdrop import VideoAtlas
from visualenv.render.plan import Distractions, VideoBackground


class BatchDistractions:
    """The distractions of a batch's envs (:attr:`current`, one per env), drawn into its scene by :meth:`draw`."""

    def __init__(
        self,
        settings: Distractions,
        scene: Any,
        num_envs: int,
        raw_colors: bool = False,
        own: Callable[[Any], object] = lambda image: None,
    ) -> None:
        """Made with the scene as one env's (its materials in the order one env draws their shifts), before the copies;
        `raw_colors`: the scene writes colours as they are (a video's frames read so: :class:`VideoAtlas`, which gives
        `own` every image it makes)."""
        on = settings.largest > 0
        #: whether the observation cameras orbit: each env's copy then follows its camera and its rays turn
        self.orbiting = on and settings.camera
        #: whether the materials read each env's shifts, and whether each env has a backdrop
        self.shifting = on and settings.colors
        self.backdropped = on and (settings.colors or bool(settings.background))
        #: whether the background is the suite's videos: each env's frame a tile of one image
        self.videos = on and isinstance(settings.background, VideoBackground)
        self._atlas: VideoAtlas | None = None
        self._scene, self._raw_colors, self._own = scene, raw_colors, own
        #: whether the floor was made see-through (one floor material serves every env: the settings' alpha is theirs)
        self.floor_faded = on and fade_floor(scene, 1.0 if settings.floor_alpha is None else settings.floor_alpha)
        materials = distracted_materials(scene)
        self._count = len(materials)
        if self.shifting:
            for i, material in enumerate(materials):
                shift_by_attribute(material, shift_name(i))
        #: each env's distraction, as its env handed it (``Frames.distractions``)
        self.current = [Distraction()] * num_envs
        self._drawn: list[Distraction | None] = [None] * num_envs
        self._values: EnvAttributes | None = None  # where each env's shifts go
        self._backdrops: Any = None  # the object that holds every env's backdrop
        self._focus: dict[tuple[int, int], tuple[float, np.ndarray]] = {}  # (camera, env) -> its orbit's centre, up
        self._orbits: dict[tuple[int, int], tuple[Distraction, np.ndarray]] = {}  # (camera, env) -> the orbit drawn

    def attach(self, values: EnvAttributes) -> None:
        """The batch's copied objects and instances, which take each env's shifts."""
        self._values = values

    def make_backdrops(self, collection: Any, places: np.ndarray, clip_end: float) -> Any:
        """Each env's backdrop about its place (``(N, 3)``: where its rays start) for cameras whose far clip is
        `clip_end`, with its own numbers (:meth:`draw`). Returns the object that holds them."""
        if self.videos:
            self._atlas = VideoAtlas(f"{collection.name} videos", len(places), self._scene, self._raw_colors, self._own)
        self._backdrops = make_backdrops(collection, f"{collection.name} backdrop", places, clip_end, self._atlas)
        return self._backdrops

    def draw(self) -> None:
        """Write every env's numbers where any env's distraction changed since the last draw (only those that changed
        reach Blender: :class:`EnvAttributes` compares)."""
        if self.current == self._drawn:
            return
        shifts = np.stack([color_shifts(d, self._count) for d in self.current])  # (N, materials + 1, 3), the sky's last
        if self.shifting and self._values is not None:
            self._values.write({shift_name(i): shifts[:, i] for i in range(self._count)})
        if self._backdrops is not None:
            write_backdrops(self._backdrops, self.current, shifts[:, -1], self._atlas)
        self._drawn = list(self.current)

    def orbited(self, camera: int, poses: np.ndarray, measure: Callable[[int], float]) -> list[np.ndarray]:
        """Each env's camera pose (``(N, 4, 4)``, each in its own copy) orbited by its distraction about its centre (and
        the world's up in its frame), measured once per env by `measure` (:func:`~visualenv.render.blender.look.distraction_scene.focus_distance`) for this `camera` (a pointer)."""
        out = []
        for k, (pose, distraction) in enumerate(zip(poses, self.current)):
            key = (camera, k)
            if key not in self._focus:
                self._focus[key] = (measure(k), world_up(pose))
            drawn = self._orbits.get(key)
            if drawn is None or drawn[0] != distraction:
                drawn = (distraction, np.array(orbit(distraction, *self._focus[key]), dtype=np.float64))
                self._orbits[key] = drawn
            out.append(pose @ drawn[1])
        return out
