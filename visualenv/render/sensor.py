"""A camera sensor model in numpy: vignetting, photon and read noise, gain and gamma on rendered bytes.

Applied after readback (never in Blender), so it costs the same whatever the
engine and keeps Cycles' image cache intact. Noise comes from the generator the
env hands in (seeded at reset), so the same seed gives the same noisy frames and
env i of a batch draws what a single env seeded s + i draws. The order of the
stages and the meaning of each figure are those of the spec's ``Sensor``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from visualenv.render.plan import CameraView, Sensor


class SensorModel:
    """One camera's sensor: call it on an (H, W, C) uint8 frame with a generator; a new uint8 frame comes back."""

    def __init__(self, sensor: Sensor, shape: tuple[int, ...]) -> None:
        self.sensor = sensor
        self.shape = shape
        height, width = shape[0], shape[1]
        self._falloff: np.ndarray | None = None
        if sensor.vignetting > 0:
            ys = (np.arange(height, dtype=np.float32) + 0.5) / height * 2 - 1
            xs = (np.arange(width, dtype=np.float32) + 0.5) / width * 2 - 1
            r2 = (ys[:, None] ** 2 + xs[None, :] ** 2) / 2  # 1 at the corners
            self._falloff = (1 - sensor.vignetting * r2)[:, :, None].astype(np.float32)
        #: identity stages are skipped, so a sensor with only noise costs only the noise
        self._gain = np.float32(sensor.gain)
        self._gamma = float(sensor.gamma)

    def __call__(self, frame: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        s = self.sensor
        v = frame.astype(np.float32)
        v *= np.float32(1 / 255)
        if self._falloff is not None:
            v *= self._falloff
        if s.shot_noise > 0:
            noise = rng.standard_normal(v.shape, dtype=np.float32)
            noise *= np.sqrt(v)
            noise *= np.float32(s.shot_noise)
            v += noise
        if s.read_noise > 0:
            noise = rng.standard_normal(v.shape, dtype=np.float32)
            noise *= np.float32(s.read_noise)
            v += noise
        if s.gain != 1:
            v *= self._gain
        np.clip(v, 0, 1, out=v)
        if self._gamma != 1:
            np.power(v, self._gamma, out=v)
        v *= np.float32(255)
        v += np.float32(0.5)
        return v.astype(np.uint8)


def sensor_models(views: Mapping[str, CameraView], spaces: Mapping[str, tuple[int, ...]]) -> dict[str, SensorModel]:
    """The sensor of each observation key whose camera declares one (``views``: key -> CameraView; ``spaces``: key -> shape)."""
    return {key: SensorModel(view.sensor, spaces[key]) for key, view in views.items() if view.sensor is not None}


def sensor_generator(np_random: np.random.Generator) -> np.random.Generator:
    """A generator for the sensor's noise, the first child of the env's seed: its draws leave the env's own stream untouched.

    Gymnasium seeds ``np_random`` from ``SeedSequence(seed)``, so a reset with seed s
    always gives the same child, and spawning does not advance the parent's numbers.
    """
    seed_seq = np_random.bit_generator.seed_seq
    assert isinstance(seed_seq, np.random.SeedSequence), "Gymnasium seeds np_random from a SeedSequence"
    return np.random.Generator(np.random.PCG64(seed_seq.spawn(1)[0]))
