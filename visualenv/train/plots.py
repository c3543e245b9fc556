"""The paper's training figures, drawn from a run folder's logs."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from visualenv.train.run_folder import RunFolder


def _read_progress(path: Path) -> dict[str, np.ndarray]:
    if not path.exists():
        return {}
    with path.open() as f:
        rows = list(csv.DictReader(f))
    columns: dict[str, list[float]] = {}
    for row in rows:
        for key, value in row.items():
            columns.setdefault(key, []).append(float(value) if value not in ("", None) else np.nan)
    return {k: np.array(v) for k, v in columns.items()}


def read_progress(run_dir: str | Path) -> dict[str, np.ndarray]:
    """Every segment of a (possibly resumed) run's SB3 progress log, joined in order."""
    tables = [t for t in (_read_progress(p) for p in RunFolder(run_dir).progress_parts()) if t]
    keys = {k for t in tables for k in t}
    joined: dict[str, np.ndarray] = {}
    for key in keys:
        joined[key] = np.concatenate([t.get(key, np.full(len(next(iter(t.values()))), np.nan)) for t in tables])
    return joined


def training_plots(run_dir: str | Path) -> list[Path]:
    """rewards.png, lengths.png, success.png, fps.png in run_dir/plots (roll-outs and evaluation)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import EngFormatter

    steps_axis = EngFormatter(sep="")  # 200k, 1M: full step counts run into each other past 100,000
    run = RunFolder(run_dir)
    out = run.plots
    out.mkdir(exist_ok=True)
    progress = read_progress(run_dir)
    steps = progress.get("time/total_timesteps", np.array([]))
    evaluations = np.load(run.evaluations) if run.evaluations.exists() else None
    paths = []
    for name, rollout_key, eval_key, label in [
        ("rewards", "rollout/ep_rew_mean", "results", "mean episode reward"),
        ("lengths", "rollout/ep_len_mean", "ep_lengths", "mean episode length"),
        ("success", "rollout/success_rate", "successes", "success rate"),
    ]:
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
        y = progress.get(rollout_key)
        if y is not None and len(steps):
            logged = np.isfinite(y)  # evaluation rows leave the roll-out columns empty
            axes[0].plot(steps[logged], y[logged])
        axes[0].set(title=f"{label}, roll-outs", xlabel="steps", ylabel=label)
        if evaluations is not None and eval_key in evaluations and len(evaluations["timesteps"]):
            values = evaluations[eval_key].mean(axis=1)
            axes[1].plot(evaluations["timesteps"], values, marker="o", markersize=3)
        axes[1].set(title=f"{label}, evaluation", xlabel="steps", ylabel=label)
        for ax in axes:
            ax.grid(alpha=0.3)
            ax.xaxis.set_major_formatter(steps_axis)
        fig.tight_layout()
        path = out / f"{name}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        paths.append(path)
    fig, ax = plt.subplots(figsize=(5, 3.8))
    fps = progress.get("time/fps")
    if fps is not None and len(steps):
        logged = np.isfinite(fps)
        ax.plot(steps[logged], fps[logged])
    ax.set(title="samples per second", xlabel="steps", ylabel="samples / s")
    ax.grid(alpha=0.3)
    ax.xaxis.set_major_formatter(steps_axis)
    fig.tight_layout()
    path = out / "fps.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    paths.append(path)
    return paths
