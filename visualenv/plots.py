"""The paper's training figures, drawn from a run folder's logs."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np


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


def training_plots(run_dir: str | Path) -> list[Path]:
    """rewards.png, lengths.png, fps.png in run_dir/plots (roll-outs and evaluation)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run = Path(run_dir)
    out = run / "plots"
    out.mkdir(exist_ok=True)
    progress = _read_progress(run / "logs" / "progress.csv")
    steps = progress.get("time/total_timesteps", np.array([]))
    evaluations = np.load(run / "evaluations.npz") if (run / "evaluations.npz").exists() else None
    paths = []
    for name, rollout_key, eval_key, label in [
        ("rewards", "rollout/ep_rew_mean", "results", "mean episode reward"),
        ("lengths", "rollout/ep_len_mean", "ep_lengths", "mean episode length"),
    ]:
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
        y = progress.get(rollout_key)
        if y is not None and len(steps):
            axes[0].plot(steps, y)
        axes[0].set(title=f"{label}, roll-outs", xlabel="steps", ylabel=label)
        if evaluations is not None and len(evaluations["timesteps"]):
            values = evaluations[eval_key].mean(axis=1)
            axes[1].plot(evaluations["timesteps"], values, marker="o", markersize=3)
        axes[1].set(title=f"{label}, evaluation", xlabel="steps", ylabel=label)
        for ax in axes:
            ax.grid(alpha=0.3)
        fig.tight_layout()
        path = out / f"{name}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        paths.append(path)
    fig, ax = plt.subplots(figsize=(5, 3.8))
    fps = progress.get("time/fps")
    if fps is not None and len(steps):
        ax.plot(steps, fps)
    ax.set(title="samples per second", xlabel="steps", ylabel="samples / s")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = out / "fps.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    paths.append(path)
    return paths
