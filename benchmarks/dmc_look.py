"""DMC-cartpole-swingup-v0's frames beside dm_control's own render of the same states: a picture and numbers.

dm_control renders with MuJoCo's OpenGL renderer (``MUJOCO_GL=egl`` unless set to
osmesa or glfw, in a child process, so that its GL context never meets Blender); visualenv's
frames are Blender's (Cycles, 1 sample, ``physics.look: mujoco``). Both start
from the same seed (their states are equal: tests/test_dmc_parity.py) and step
the same actions with no action repeat. Prints, per state, the mean colour of
each region of visualenv's segmentation (sky, floor and rails, cart, pole) in
both frames, and writes one PNG: a row per state, dm_control's frame on the
left and visualenv's on the right, each pixel 4 x 4.

    python benchmarks/dmc_look.py --out dmc_look.png
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

SPEC = Path(__file__).resolve().parent.parent / "specs" / "dmc" / "cartpole_swingup.yaml"
#: the states compared: (seed, control steps of its action sequence before the frame)
STATES = ((0, 0), (1, 40), (2, 120))
SIZE = 84
#: regions of visualenv's segmentation: the sky (id 0), the world body's geoms (floor, rails), the cart, the pole
REGIONS = ("sky", "world", "cart", "pole_1")

_DM_CONTROL = """
import json, os, sys
import numpy as np
from dm_control import suite
states, actions, out, size = json.loads(sys.argv[1]), np.load(sys.argv[2]), sys.argv[3], int(sys.argv[4])
frames = []
for (seed, steps), acts in zip(states, actions):
    env = suite.load("cartpole", "swingup", task_kwargs={"random": seed})
    env.reset()
    for a in acts[:steps]:
        env.step(a)
    frames.append(env.physics.render(size, size, camera_id=0))
np.save(out, np.stack(frames))
sys.stdout.flush()
os._exit(0)  # MuJoCo's EGL context complains when it is freed at exit
"""


def actions(states: tuple[tuple[int, int], ...]) -> np.ndarray:
    """Each state's action sequence (seeded by its seed), (states, longest, 1) float64 in [-1, 1]."""
    longest = max([steps for _, steps in states] + [1])
    return np.stack([np.random.default_rng(seed).uniform(-1, 1, size=(longest, 1)) for seed, _ in states])


def dm_control_frames(states: tuple[tuple[int, int], ...] = STATES) -> np.ndarray:
    """dm_control's camera-0 frames of the states, (states, 84, 84, 3); RuntimeError with its words if it cannot render."""
    with tempfile.TemporaryDirectory() as folder:
        acts, out = Path(folder) / "actions.npy", Path(folder) / "frames.npy"
        np.save(acts, actions(states))
        backend = os.environ.get("MUJOCO_GL")  # a test process may have set "disable" for dm_control's import
        done = subprocess.run([sys.executable, "-c", _DM_CONTROL, json.dumps(states), str(acts), str(out), str(SIZE)], capture_output=True,
                              text=True, env={**os.environ, "MUJOCO_GL": backend if backend in ("egl", "osmesa", "glfw") else "egl"})
        if done.returncode != 0 or not out.exists():
            raise RuntimeError(f"dm_control could not render: {done.stderr.strip()[-800:]}")
        return np.load(out)


def segmented_spec(folder: Path) -> Path:
    """The bundled spec with a segmentation camera beside its colour one (its model path made absolute)."""
    data = yaml.safe_load(SPEC.read_text(encoding="utf-8"))
    data["physics"]["model"] = str((SPEC.parent / data["physics"]["model"]).resolve())
    view = data["observation"]
    data["observation"] = {"cameras": {"eye": view, "mask": {**view, "color": "segmentation"}}}
    out = folder / "cartpole_segmented.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return out


def visualenv_frames(states: tuple[tuple[int, int], ...] = STATES) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """visualenv's frames of the states (states, 84, 84, 3), their segmentation (states, 84, 84) and its ids."""
    import visualenv

    frames, masks, ids = [], [], {}
    with tempfile.TemporaryDirectory() as folder:
        spec = segmented_spec(Path(folder))
        for (seed, steps), sequence in zip(states, actions(states)):
            env = visualenv.make(spec, action_repeat=1)
            try:
                obs, _ = env.reset(seed=seed)
                for a in sequence[:steps]:
                    obs, *_ = env.step(a)
                frames.append(obs["eye"])
                masks.append(obs["mask"][..., 0])
                ids = env.unwrapped.segmentation_ids
            finally:
                env.close()
    return np.stack(frames), np.stack(masks), ids


def region_means(frame: np.ndarray, mask: np.ndarray, ids: dict[str, int]) -> dict[str, np.ndarray]:
    """The mean colour of each region of the mask (:data:`REGIONS`) in `frame`, off the regions' edges (where one
    renderer's antialiasing blends two regions and the other's one sample picks either)."""
    out = {}
    for region in REGIONS:
        inside = mask == (0 if region == "sky" else ids[region])
        for shift in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            inside &= np.roll(mask == (0 if region == "sky" else ids[region]), shift, axis=(0, 1))
        if inside.any():
            out[region] = frame[inside].astype(float).mean(axis=0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("dmc_look.png"), help="the side-by-side picture (PNG)")
    args = parser.parse_args()
    theirs = dm_control_frames()
    ours, masks, ids = visualenv_frames()
    for (seed, steps), a, b, mask in zip(STATES, theirs, ours, masks):
        print(f"seed {seed}, {steps} steps: mean |difference| {np.abs(a.astype(int) - b.astype(int)).mean():.1f} levels")
        mine = region_means(b, mask, ids)
        for region, colour in region_means(a, mask, ids).items():
            print(f"  {region:7s} dm_control {np.round(colour).astype(int)}  visualenv {np.round(mine[region]).astype(int)}")
    from PIL import Image

    rows = np.concatenate([np.concatenate([a, np.full((SIZE, 2, 3), 255, np.uint8), b], axis=1) for a, b in zip(theirs, ours)], axis=0)
    Image.fromarray(np.repeat(np.repeat(rows, 4, axis=0), 4, axis=1)).save(args.out)
    print(f"wrote {args.out}: dm_control left, visualenv right")


if __name__ == "__main__":
    main()
