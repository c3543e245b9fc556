"""Engine, preset, device and thread configuration of a Blender scene.

An :class:`EngineConfig` is the complete set of engine knobs one render needs
(engine, samples, bounces, denoising, pixel filter). :func:`apply_config` writes
only the fields that differ from the previously applied config, so switching
between the observation settings and the human-view settings costs a few
attribute writes.

Presets (Cycles):

* ``fast`` (training): 1 sample, every bounce 0, no denoising, no adaptive
  sampling, a 1-pixel box filter (crisp, deterministic pixels).
* ``quality`` (previews): 16 samples, 4 bounces, Blackman-Harris filter, no
  denoising (OpenImageDenoise runs on the CPU but adds seconds per frame).
  About a second per 400x400 view on a CPU (``visualenv preview`` renders it).

``samples`` / ``bounces`` in the spec (or the renderer options) override the
preset. Workbench ignores bounces and maps samples to its anti-aliasing
levels; EEVEE maps samples to ``taa_render_samples``.
"""

from __future__ import annotations

import logging
import sys
import warnings
from dataclasses import dataclass
from typing import Any

import bpy

from visualenv.compat.blender import use_cached_kernels
from visualenv.render.blender.runtime.devices import compile_notice, detect_gpu, kernel_facts
from visualenv.render.plan import RenderSettings

log = logging.getLogger("visualenv.render")

ENGINE_IDS = {"cycles": "CYCLES", "workbench": "BLENDER_WORKBENCH", "eevee": "BLENDER_EEVEE"}
_BOUNCES = ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces")
#: passes through see-through surfaces (a colour with alpha < 1), only in scenes that have one: with
#: any, Cycles traces shadows through every surface, which raises the raw render floor
#: (``visualenv bench``; docs/performance.md)
TRANSPARENT_BOUNCES = 8
_WORKBENCH_AA = ((1, "OFF"), (4, "FXAA"), (5, "5"), (8, "8"), (11, "11"), (16, "16"))


@dataclass(frozen=True)
class EngineConfig:
    """Engine settings for one kind of render (observation or human view)."""

    engine: str  # cycles | workbench | eevee
    samples: int
    bounces: int
    denoise: bool
    filter: str  # Cycles pixel_filter_type
    filter_width: float


PRESETS: dict[str, dict[str, Any]] = {
    "fast": dict(samples=1, bounces=0, denoise=False, filter="BOX", filter_width=1.0),
    # OpenImageDenoise works on the CPU but adds seconds per 400x400 frame: off
    "quality": dict(samples=16, bounces=4, denoise=False, filter="BLACKMAN_HARRIS", filter_width=1.5),
}

#: a depth observation is a Cycles render of camera depth (Workbench and EEVEE cannot override materials)
DEPTH_CONFIG = EngineConfig("cycles", 1, 0, False, "BOX", 1.0)


def depth_config(obs: EngineConfig) -> EngineConfig:
    """Depth renders share the observations' Cycles config (no setting changes between views)."""
    return obs if obs.engine == "cycles" else DEPTH_CONFIG


def make_config(settings: RenderSettings, preset: str) -> EngineConfig:
    """The config of `preset` with the spec's overrides (samples, bounces; make()'s options are merged into `settings`)."""
    values = dict(PRESETS[preset])
    if settings.samples is not None:
        values["samples"] = settings.samples
    if settings.bounces is not None:
        values["bounces"] = settings.bounces
    return EngineConfig(engine=settings.engine, **values)


def view_config(obs: EngineConfig, preset: str) -> EngineConfig:
    """The human view's config: 'fast' is the observations' config; 'quality' is the
    quality preset on the observations' engine, with at least their samples and bounces."""
    if preset == "fast":
        return obs
    q = PRESETS["quality"]
    return EngineConfig(
        obs.engine,
        max(q["samples"], obs.samples),
        max(q["bounces"], obs.bounces),
        q["denoise"],
        q["filter"],
        q["filter_width"],
    )


# -- devices -----------------------------------------------------------------------------------------

_warned: set[str] = set()


def _warn_once(key: str, message: str) -> None:
    if key not in _warned:
        _warned.add(key)
        warnings.warn(message, RuntimeWarning, stacklevel=3)


def _compile_notice_once(backend: str) -> None:
    """Before the first GPU render of this process: say so when the driver must compile Cycles' kernels first (minutes)."""
    if "compile" in _warned:
        return
    _warned.add("compile")
    use_cached_kernels()  # what `visualenv compile-kernels` compiled ahead, before Cycles loads its kernels
    notice = compile_notice(kernel_facts(backend))
    if notice:
        print(notice, file=sys.stderr, flush=True)


def resolve_device(device: str) -> str:
    """'CPU' or 'GPU' for a spec's cpu|gpu|auto, with a one-time message on fallback."""
    if device == "cpu":
        return "CPU"
    backend = detect_gpu()
    if backend:
        log.info("Cycles renders on the GPU (%s)", backend)
        _compile_notice_once(backend)
        return "GPU"
    if device == "gpu":
        _warn_once(
            "gpu",
            "render.device is 'gpu' but Blender found no CUDA/OptiX/HIP/Metal/oneAPI device: rendering on the CPU",
        )
    else:
        log.info("render.device 'auto': no GPU found, rendering on the CPU")
    return "CPU"


# -- writing settings to a scene ---------------------------------------------------------------------


def configure_scene(scene: Any, *, device: str, threads: int, noise: str = "independent", raw: bool = False) -> None:
    """Settings that never change between renders: colour management (`raw`: colours written as they are), output, threads, device."""
    r = scene.render
    r.image_settings.media_type = "IMAGE"  # a file saved for video or multilayer EXR output has no BMP
    r.use_multiview = False
    r.use_stamp = False  # metadata burnt into the pixels
    r.use_freestyle = False
    r.resolution_percentage = 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.use_border = False
    r.film_transparent = False
    r.dither_intensity = 0.0  # dithering adds noise to 8-bit output
    r.use_compositing = False
    r.use_sequencer = False
    r.use_persistent_data = True  # keeps Cycles' scene between renders (results/benchmarks/single-env-vm.md)
    r.use_motion_blur = False
    r.use_simplify = False
    if threads:
        r.threads_mode = "FIXED"
        r.threads = threads
    else:
        r.threads_mode = "AUTO"
    set_color_management(scene, raw=raw)
    c = scene.cycles
    c.device = device
    c.use_adaptive_sampling = False
    c.use_animated_seed = False
    c.seed = 0
    # every pixel draws the same random numbers: its value does not depend on its place in the image
    if noise == "shared":
        c.sampling_pattern = "TABULATED_SOBOL"
        c.auto_scrambling_distance = False
        c.scrambling_distance = 0.0
    c.use_auto_tile = False
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.caustics_reflective = False
    c.caustics_refractive = False
    c.film_exposure = 1.0
    c.time_limit = 0.0  # a time limit cuts renders short at a load-dependent sample
    c.use_layer_samples = "IGNORE"
    c.use_guiding = False
    d = scene.display.shading  # workbench: material colours, studio light
    d.light = "STUDIO"
    d.color_type = "MATERIAL"


def quiet_emission(scene: Any) -> None:
    """Emissive surfaces glow but are not sampled as lights (``emission_sampling='NONE'``).

    At 1 sample per pixel Cycles otherwise splits its light samples between the
    lamps and every emissive surface, which leaves salt-and-pepper black pixels
    on lit surfaces. The cost: an emissive object lights its surroundings only
    through bounces (none in the fast preset).
    """
    materials = {slot.material for obj in scene.objects for slot in obj.material_slots if slot.material is not None}
    for mat in materials:
        mat.cycles.emission_sampling = "NONE"


def set_color_management(scene: Any, *, raw: bool) -> None:
    """'Standard' (plain sRGB) for colour, 'Raw' (values written as they are) for depth, ids and MuJoCo's look."""
    vs = scene.view_settings
    scene.display_settings.display_device = "sRGB"
    vs.view_transform = "Raw" if raw else "Standard"
    vs.look = "None"
    vs.exposure = 0.0
    vs.gamma = 1.0
    vs.use_curve_mapping = False
    vs.use_white_balance = False


def apply_config(scene: Any, config: EngineConfig, previous: EngineConfig | None, *, see_through: bool = False) -> None:
    """Write the fields of `config` that differ from `previous` (all of them when None).

    `see_through`: the scene has surfaces with alpha below 1, which need passes of their own.
    """

    def changed(field: str) -> bool:
        return previous is None or getattr(previous, field) != getattr(config, field)

    if changed("engine") and scene.render.engine != ENGINE_IDS[config.engine]:
        scene.render.engine = ENGINE_IDS[config.engine]  # any setting of it frees every scene's persistent Cycles data
    c = scene.cycles
    if changed("samples"):
        c.samples = config.samples
        c.preview_samples = config.samples
        scene.eevee.taa_render_samples = config.samples
        scene.display.render_aa = next((aa for n, aa in reversed(_WORKBENCH_AA) if config.samples >= n), "OFF")
    if changed("bounces"):
        for name in _BOUNCES:
            setattr(c, name, config.bounces)
        c.transparent_max_bounces = TRANSPARENT_BOUNCES if see_through else config.bounces
    if changed("denoise"):
        c.use_denoising = config.denoise and _oidn_available()
    if changed("filter"):
        c.pixel_filter_type = config.filter
    if changed("filter_width"):
        c.filter_width = config.filter_width


def _oidn_available() -> bool:
    return bool(getattr(bpy.app.build_options, "openimagedenoise", True))


def engine_warnings(config: EngineConfig, device: str) -> None:
    """Say once when a choice will be slow."""
    if config.engine == "eevee" and detect_gpu() is None:
        _warn_once(
            "eevee",
            "EEVEE without a GPU renders in software and takes seconds per frame: use engine 'cycles' (or 'workbench') for training",
        )
