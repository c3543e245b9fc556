"""Folders the commands write to, made before any work so a bad path fails first."""

from __future__ import annotations

from pathlib import Path

from visualenv.errors import VisualEnvError


def make_dir(path: Path) -> Path:
    """``mkdir -p`` that reports a folder it cannot make as a user error, before any work is done."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise VisualEnvError(f"cannot create the folder {path}: {exc.strerror or exc}") from None
    return path
