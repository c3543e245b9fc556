"""How much distractions change what the agent sees: each DMC task's first frames at the Distracting Control Suite's
difficulties, against the same frames without distractions.

For each bundled DMC id and difficulty (0.1, 0.2, 0.3, every kind, fixed per episode), the mean absolute difference
of the first observation (84x84 RGB) after ``reset(seed=s)`` from the plain env's, over the seeds; and one picture:
a row per task, its plain frame of seed 0 and the distracted ones left to right.

    python benchmarks/distractions.py --seeds 4 --out distractions.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

IDS = ("DMC-cartpole-swingup-v0", "DMC-reacher-easy-v0", "DMC-cheetah-run-v0", "DMC-finger-spin-v0", "DMC-ball_in_cup-catch-v0",
       "DMC-walker-walk-v0")
LEVELS = (0.1, 0.2, 0.3)


def first_frames(env_id: str, level: float, seeds: range) -> list[np.ndarray]:
    """The first observation after each seeded reset, at `level` (0: none)."""
    import visualenv

    env = visualenv.make(env_id, distractions=level)
    try:
        return [env.reset(seed=seed)[0] for seed in seeds]
    finally:
        env.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--out", type=Path, default=Path("distractions.png"), help="the picture (PNG)")
    parser.add_argument("--scale", type=int, default=2, help="pixels of the picture per frame pixel")
    args = parser.parse_args()
    seeds = range(args.seeds)
    print("| id | " + " | ".join(f"difficulty {level}" for level in LEVELS) + " |")
    print("| --- |" + " ---: |" * len(LEVELS))
    rows = []
    for env_id in IDS:
        clean = first_frames(env_id, 0.0, seeds)
        row, figures = [clean[0]], []
        for level in LEVELS:
            frames = first_frames(env_id, level, seeds)
            figures.append(np.mean([np.abs(a.astype(int) - b.astype(int)).mean() for a, b in zip(clean, frames)]))
            row.append(frames[0])
        rows.append(np.concatenate(row, axis=1))
        print(f"| `{env_id}` | " + " | ".join(f"{value:.1f}" for value in figures) + " |")
    from PIL import Image

    picture = np.concatenate(rows, axis=0)
    Image.fromarray(np.repeat(np.repeat(picture, args.scale, axis=0), args.scale, axis=1)).save(args.out)
    print(f"wrote {args.out}: per task, plain then difficulty " + ", ".join(str(level) for level in LEVELS))


if __name__ == "__main__":
    main()
