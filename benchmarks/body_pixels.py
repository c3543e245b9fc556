"""How a MuJoCo body looks at the training preset: the share of its pixels that are black, per physics.look.

Each of Gymnasium's models named is seen through its ``track`` camera at 84x84
(the training preset: 1 sample, no bounces) beside a segmentation camera, and
the pixels of every body but the world's (the floor) are counted: how many are
below 10 of 255 in all three channels, their median brightest channel, their
mean colour. ``physical`` is Blender's light (what every MuJoCo spec had before
``physics.look``); ``mujoco`` is MuJoCo's look.

    python benchmarks/body_pixels.py humanoid hopper half_cheetah walker2d ant
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

SPEC = """\
id: Body-v0
physics: {{model: "package:gymnasium.envs.mujoco/assets/{model}.xml", look: {look}}}
observation:
  cameras:
    eye: {{camera: {camera}, resolution: [84, 84], color: rgb}}
    mask: {{camera: {camera}, resolution: [84, 84], color: segmentation}}
reward: 0.0
"""


def body_pixels(model: str, look: str, camera: str = "track") -> tuple[np.ndarray, np.ndarray]:
    """The first frame (after reset with seed 0) and the mask of the body's pixels (every id but the sky and the world's)."""
    import visualenv

    with tempfile.TemporaryDirectory() as folder:
        spec = Path(folder) / f"{model}.yaml"
        spec.write_text(SPEC.format(model=model, look=look, camera=camera), encoding="utf-8")
        env = visualenv.make(spec)
        try:
            obs, _ = env.reset(seed=0)
            ids = env.unwrapped.segmentation_ids
        finally:
            env.close()
    mask = obs["mask"][..., 0]
    return obs["eye"], (mask != 0) & (mask != ids.get("world", -1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="+", help="Gymnasium's MJCF files by stem (humanoid, hopper, ...)")
    args = parser.parse_args()
    for model in args.models:
        for look in ("physical", "mujoco"):
            frame, body = body_pixels(model, look)
            brightest = frame[body].max(axis=1)
            print(f"{model:13s} {look:8s} {body.sum():4d} body pixels: {100 * (brightest < 10).mean():5.1f} % below 10 of 255, "
                  f"median brightest channel {np.median(brightest):5.1f}, mean colour {np.round(frame[body].mean(axis=0)).astype(int)}")


if __name__ == "__main__":
    main()
