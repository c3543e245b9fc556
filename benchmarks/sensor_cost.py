"""The camera sensor model's cost per frame (observation.sensor), by resolution and colour, in numpy after readback.

    python benchmarks/sensor_cost.py

Times :class:`visualenv.render.sensor.SensorModel` on a random uint8 frame with
every stage on (vignetting, shot and read noise, gain, gamma) and with read
noise alone, per call, after one warm-up call.
"""

import time

import numpy as np

from visualenv.render.sensor import SensorModel
from visualenv.spec.models import Sensor

FULL = Sensor(read_noise=0.02, shot_noise=0.03, gain=1.2, gamma=0.9, vignetting=0.3)
READ_ONLY = Sensor(read_noise=0.02)


def per_frame_ms(sensor: Sensor, shape: tuple[int, int, int], calls: int) -> float:
    model = SensorModel(sensor, shape)
    frame = np.random.default_rng(0).integers(0, 256, shape, dtype=np.uint8)
    rng = np.random.default_rng(1)
    model(frame, rng)
    start = time.perf_counter()
    for _ in range(calls):
        model(frame, rng)
    return (time.perf_counter() - start) / calls * 1000


print(f"{'frame':>14} {'all stages ms':>14} {'read noise ms':>14}")
for side in (64, 100, 256, 512):
    for channels in (1, 3):
        shape = (side, side, channels)
        calls = max(20, 2_000_000 // (side * side * channels))
        label = f"{side}x{side}x{channels}"
        print(f"{label:>14} {per_frame_ms(FULL, shape, calls):>14.3f} {per_frame_ms(READ_ONLY, shape, calls):>14.3f}")
