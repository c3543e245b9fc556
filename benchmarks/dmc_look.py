"""The DMC tasks' frames beside dm_control's own render of the same states: a picture and numbers.

dm_control renders with MuJoCo's OpenGL renderer (``MUJOCO_GL=egl`` unless set to
osmesa or glfw, in a child process, so that its GL context never meets Blender); visualenv's
frames are Blender's (Cycles, 1 sample, ``physics.look: mujoco``). Both start
from the same seed (their states are equal: tests/specs/test_dmc_parity.py) and step
the same actions with no action repeat. Prints, per state, the mean colour of
each region of visualenv's segmentation (the sky, each body's geoms; the
world body's: floor and decorations) in both frames, and writes one PNG: a row
per state, dm_control's frame on the left and visualenv's on the right, each
pixel 4 x 4 (``--scale``).

    python benchmarks/dmc_look.py --out dmc_look.png                 # cartpole swingup
    python benchmarks/dmc_look.py --task all --states 1 --out dmc_tasks.png
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

SPECS = Path(__file__).resolve().parent.parent / "specs" / "dmc"
#: dm_control's domain and task of each bundled spec, by the name --task takes
TASKS = {
    "cartpole": ("cartpole", "swingup", "cartpole_swingup.yaml"),
    "reacher": ("reacher", "easy", "reacher_easy.yaml"),
    "cheetah": ("cheetah", "run", "cheetah_run.yaml"),
    "finger": ("finger", "spin", "finger_spin.yaml"),
    "ball_in_cup": ("ball_in_cup", "catch", "ball_in_cup_catch.yaml"),
    "walker": ("walker", "walk", "walker_walk.yaml"),
    "pendulum": ("pendulum", "swingup", "pendulum_swingup.yaml"),
    "acrobot": ("acrobot", "swingup", "acrobot_swingup.yaml"),
    "hopper": ("hopper", "stand", "hopper_stand.yaml"),
    "humanoid": ("humanoid", "walk", "humanoid_walk.yaml"),
    "quadruped": ("quadruped", "walk", "quadruped_walk.yaml"),
}
#: DrQ-v2's camera where it is not camera 0: quadruped's camera 2 (its spec's camera)
CAMERA_ID = {"quadruped": 2}
#: the states compared: (seed, control steps of its action sequence before the frame)
STATES = ((0, 0), (1, 40), (2, 120))
SIZE = 84

_DM_CONTROL = """
import json, os, sys
import numpy as np
from dm_control import suite
states, actions, out, size = json.loads(sys.argv[1]), np.load(sys.argv[2]), sys.argv[3], int(sys.argv[4])
domain, task, camera = sys.argv[5], sys.argv[6], int(sys.argv[7])
frames = []
for (seed, steps), acts in zip(states, actions):
    env = suite.load(domain, task, task_kwargs={"random": seed})
    env.reset()
    for a in acts[:steps]:
        env.step(a)
    frames.append(env.physics.render(size, size, camera_id=camera))
np.save(out, np.stack(frames))
sys.stdout.flush()
os._exit(0)  # MuJoCo's EGL context complains when it is freed at exit
"""


def actions(states: tuple[tuple[int, int], ...], size: int) -> np.ndarray:
    """Each state's action sequence (seeded by its seed), (states, longest, size) float64 in [-1, 1]."""
    longest = max([steps for _, steps in states] + [1])
    return np.stack([np.random.default_rng(seed).uniform(-1, 1, size=(longest, size)) for seed, _ in states])


def action_size(task: str) -> int:
    """The task's number of actuators (its spec's actions)."""
    import visualenv

    env = visualenv.make(SPECS / TASKS[task][2], render=False)
    try:
        return int(env.action_space.shape[0])
    finally:
        env.close()


def dm_control_frames(states: tuple[tuple[int, int], ...] = STATES, task: str = "cartpole") -> np.ndarray:
    """dm_control's frames of the states from the spec's camera (camera 0; quadruped's 2), (states, 84, 84, 3); RuntimeError with its words if it cannot render."""
    domain, name, _ = TASKS[task]
    with tempfile.TemporaryDirectory() as folder:
        acts, out = Path(folder) / "actions.npy", Path(folder) / "frames.npy"
        np.save(acts, actions(states, action_size(task)))
        backend = os.environ.get("MUJOCO_GL")  # a test process may have set "disable" for dm_control's import
        done = subprocess.run(
            [
                sys.executable,
                "-c",
                _DM_CONTROL,
                json.dumps(states),
                str(acts),
                str(out),
                str(SIZE),
                domain,
                name,
                str(CAMERA_ID.get(task, 0)),
            ],
            capture_output=True,
            text=True,
            env={**os.environ, "MUJOCO_GL": backend if backend in ("egl", "osmesa", "glfw") else "egl"},
        )
        if done.returncode != 0 or not out.exists():
            raise RuntimeError(f"dm_control could not render: {done.stderr.strip()[-800:]}")
        return np.load(out)


def segmented_spec(folder: Path, task: str) -> Path:
    """The task's bundled spec with a segmentation camera beside its colour one (its model path made absolute)."""
    spec = SPECS / TASKS[task][2]
    data = yaml.safe_load(spec.read_text(encoding="utf-8"))
    data["physics"]["model"] = str((spec.parent / data["physics"]["model"]).resolve())
    view = data["observation"]
    data["observation"] = {"cameras": {"eye": view, "mask": {**view, "color": "segmentation"}}}
    out = folder / f"{task}_segmented.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return out


def visualenv_frames(
    states: tuple[tuple[int, int], ...] = STATES, task: str = "cartpole"
) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """visualenv's frames of the states (states, 84, 84, 3), their segmentation (states, 84, 84) and its ids."""
    import visualenv

    frames, masks, ids = [], [], {}
    with tempfile.TemporaryDirectory() as folder:
        spec = segmented_spec(Path(folder), task)
        for (seed, steps), sequence in zip(states, actions(states, action_size(task))):
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


def region_means(frame: np.ndarray, mask: np.ndarray, ids: dict[str, int], least: int = 4) -> dict[str, np.ndarray]:
    """The mean colour in `frame` of each region of the mask (the sky, each id) with at least `least` pixels off the
    regions' edges (where one renderer's antialiasing blends two regions and the other's one sample picks either)."""
    out = {}
    for region, ident in {"sky": 0, **ids}.items():
        inside = mask == ident
        for shift in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            inside &= np.roll(mask == ident, shift, axis=(0, 1))
        if inside.sum() >= least:
            out[region] = frame[inside].astype(float).mean(axis=0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("dmc_look.png"), help="the side-by-side picture (PNG)")
    parser.add_argument("--task", default="cartpole", choices=[*TASKS, "all"])
    parser.add_argument("--states", type=int, default=len(STATES), help=f"how many of the states {STATES} to compare")
    parser.add_argument("--scale", type=int, default=4, help="pixels of the picture per frame pixel")
    args = parser.parse_args()
    rows = []
    for task in TASKS if args.task == "all" else [args.task]:
        states = STATES[: args.states]
        theirs = dm_control_frames(states, task)
        ours, masks, ids = visualenv_frames(states, task)
        for (seed, steps), a, b, mask in zip(states, theirs, ours, masks):
            print(
                f"{task}, seed {seed}, {steps} steps: mean |difference| {np.abs(a.astype(int) - b.astype(int)).mean():.1f} levels"
            )
            mine = region_means(b, mask, ids)
            for region, colour in region_means(a, mask, ids).items():
                print(
                    f"  {region:12s} dm_control {np.round(colour).astype(int)}  visualenv {np.round(mine[region]).astype(int)}"
                )
            rows.append(np.concatenate([a, np.full((SIZE, 2, 3), 255, np.uint8), b], axis=1))
    from PIL import Image

    Image.fromarray(np.repeat(np.repeat(np.concatenate(rows, axis=0), args.scale, axis=0), args.scale, axis=1)).save(
        args.out
    )
    print(f"wrote {args.out}: dm_control left, visualenv right")


if __name__ == "__main__":
    main()
