"""Render reset + 5 steps (fixed seed) of a few bundled ids, single and as a batch of 2, and save or compare the frames.

    python benchmarks/frames_snapshot.py save OUT.npz       # before a change
    python benchmarks/frames_snapshot.py compare OUT.npz    # after it: every array bit for bit
"""

from __future__ import annotations

import sys

import numpy as np

import visualenv
from visualenv.env.batch import BatchedVectorEnv

IDS = ("VisualCartPole-v0", "Hover2D-v0", "Goalie-v0", "DMC-cartpole-swingup-v0")
STEPS = 5


def _flat(prefix: str, obs, out: dict) -> None:
    if isinstance(obs, dict):
        for key, value in obs.items():
            out[f"{prefix}/{key}"] = np.array(value)
    else:
        out[prefix] = np.array(obs)


def frames() -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for env_id in IDS:
        for distract in (0, "medium"):
            tag = f"{env_id}/d{distract}"
            env = visualenv.make(env_id, render_mode="rgb_array", distractions=distract)
            obs, _ = env.reset(seed=3)
            _flat(f"{tag}/single/0", obs, out)
            env.action_space.seed(3)
            for t in range(STEPS):
                obs, *_ = env.step(env.action_space.sample())
                _flat(f"{tag}/single/{t + 1}", obs, out)
            out[f"{tag}/single/view"] = np.array(env.render())
            env.close()
            batch = BatchedVectorEnv(env_id, 2, render_mode="rgb_array", distractions=distract)
            obs, _ = batch.reset(seed=3)
            _flat(f"{tag}/batch/0", obs, out)
            batch.action_space.seed(3)
            for t in range(STEPS):
                obs, *_ = batch.step(batch.action_space.sample())
                _flat(f"{tag}/batch/{t + 1}", obs, out)
            out[f"{tag}/batch/view"] = np.stack(batch.render())
            batch.close()
            print(tag, "done", flush=True)
    return out


if __name__ == "__main__":
    mode, path = sys.argv[1], sys.argv[2]
    got = frames()
    if mode == "save":
        np.savez_compressed(path, **got)
        print(f"saved {len(got)} arrays")
    else:
        want = dict(np.load(path))
        bad = [k for k in want if k not in got or not np.array_equal(want[k], got[k])]
        extra = sorted(set(got) - set(want))
        print(f"{len(want)} arrays compared; differing: {bad or 'none'}; new: {extra or 'none'}")
        sys.exit(1 if bad or extra else 0)
