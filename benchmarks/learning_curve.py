"""A run's learning curve in frames beside published points: the periodic evaluations of a `visualenv train` run
folder (evaluations.npz), each env step counted as the spec's action repeat of frames, as DMC papers count them.

    python benchmarks/learning_curve.py RUN_DIR OUT_DIR [--published drq] [--beside CURVE_CSV=LABEL ...] [--final FILE]

Writes OUT_DIR/curve.png (mean return of each evaluation, its standard deviation shaded, the published points with
their error bars, each `--beside` curve.csv of an earlier run under its label, and with `--final` a `visualenv eval
-o` file of the run's final model, drawn at the last step the run took: its results.json's `steps`) and
OUT_DIR/curve.csv (steps, frames, mean, std, the run's wall-clock seconds at that evaluation where the progress log
has them).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

#: published mean returns (and standard deviations) at so many frames, by spec id and method
PUBLISHED = {
    # Kostrikov, Yarats and Fergus 2020, "Image Augmentation Is All You Need", Table 1 (PlaNet benchmark, 10 seeds)
    "drq": {"DMC-cartpole-swingup-v0": {"label": "DrQ (paper)", "points": [(100_000, 759, 92), (500_000, 868, 10)]}},
}


def evaluations(run_dir: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The steps, mean returns and standard deviations of the run's periodic evaluations."""
    with np.load(run_dir / "evaluations.npz") as data:
        steps = np.asarray(data["timesteps"], dtype=np.int64)
        results = np.asarray(data["results"], dtype=np.float64)
    return steps, results.mean(axis=1), results.std(axis=1)


def wall_times(run_dir: Path, steps: np.ndarray) -> list[float | None]:
    """The run's elapsed seconds when it had taken each of `steps` (the first progress row at or past it), a resumed
    run's segments added end to end (each segment's log starts its clock at 0)."""
    from visualenv.train.run_folder import RunFolder

    rows: list[tuple[int, float]] = []
    for part in RunFolder(run_dir).progress_parts():
        offset = rows[-1][1] if rows else 0.0
        with part.open() as f:
            rows += [
                (int(float(r["time/total_timesteps"])), offset + float(r["time/time_elapsed"]))
                for r in csv.DictReader(f)
                if r.get("time/time_elapsed") and r.get("time/total_timesteps")
            ]
    return [next((round(t) for s, t in rows if s >= step), None) for step in steps]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--published", default="drq", choices=sorted(PUBLISHED))
    parser.add_argument("--beside", action="append", default=[], help="an earlier run's curve.csv=LABEL to draw too")
    parser.add_argument("--final", type=Path, help="`visualenv eval -o` figures of the run's final model")
    args = parser.parse_args()
    from visualenv.train.run_folder import read_run

    run = read_run(args.run_dir)
    assert run.record is not None, f"{args.run_dir}: not a run folder (no config.json)"
    spec_id = run.record["spec"]["id"]
    import visualenv

    repeat = visualenv.make(spec_id, render=False).unwrapped.action_repeat
    steps, means, stds = evaluations(args.run_dir)
    if args.final:  # the final model's evaluation, at the last step the run took
        final = json.loads(args.final.read_text())
        returns = np.asarray(final["per_episode"]["returns"], dtype=np.float64)
        assert run.results is not None, f"{args.run_dir}: --final needs the run's results.json (its steps)"
        steps = np.append(steps, run.results["steps"])
        means, stds = np.append(means, returns.mean()), np.append(stds, returns.std())
    frames = steps * repeat
    args.out_dir.mkdir(parents=True, exist_ok=True)
    with (args.out_dir / "curve.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(("steps", "frames", "mean_return", "std_return", "wall_s"))
        for row in zip(steps, frames, means, stds, wall_times(args.run_dir, steps)):
            writer.writerow((int(row[0]), int(row[1]), round(row[2], 2), round(row[3], 2), row[4]))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(6, 4))
    axes.plot(frames, means, marker="o", label="visualenv train --algo sac --augment shift")
    axes.fill_between(frames, means - stds, means + stds, alpha=0.2)
    for given in args.beside:
        path, _, label = given.partition("=")
        with open(path, newline="") as f:
            earlier = [(int(r["frames"]), float(r["mean_return"])) for r in csv.DictReader(f)]
        axes.plot(*zip(*earlier), marker=".", linestyle="--", color="grey", label=label or path)
    published = PUBLISHED[args.published].get(spec_id)
    if published:
        x, y, e = zip(*published["points"])
        axes.errorbar(x, y, yerr=e, fmt="s", color="black", capsize=4, label=published["label"])
    axes.set_xlabel(f"frames (env steps x action repeat {repeat})")
    axes.set_ylabel("mean evaluation return")
    axes.set_title(spec_id)
    axes.set_ylim(0, 1000)
    axes.legend(loc="lower right")
    figure.tight_layout()
    figure.savefig(args.out_dir / "curve.png", dpi=100)
    print(
        f"wrote {args.out_dir / 'curve.png'} and curve.csv: {len(steps)} evaluations, up to {int(frames[-1]):,} frames"
    )


if __name__ == "__main__":
    main()
