"""The files a spec's live edit rebuilds on: the spec and every file it names, polled for changes.

Polling each file's modification time and size twice a second costs microseconds and needs no library; an
editor that saves by writing a new file and renaming it is seen too (the path is polled, not the file).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable

from visualenv.spec.loader import LoadedSpec


def named_files(loaded: LoadedSpec) -> list[Path]:
    """The spec file and the files it names that exist: ``scene.file`` (.blend), ``physics.model`` (MJCF), textures,
    meshes, height maps. Every text of the spec that is the path of a file beside it counts, so a new kind of file
    field is watched without a change here."""
    base = loaded.base_dir
    found = {Path(loaded.file).resolve(): None}
    for text in _texts(loaded.spec.model_dump()):
        if not text or len(text) > 4096 or "\n" in text:
            continue
        try:
            path = (base / text).resolve()
            if path.is_file():
                found[path] = None
        except (OSError, ValueError):
            continue
    return list(found)


def _texts(value: Any) -> Iterable[str]:
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for item in value.values():
            yield from _texts(item)
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from _texts(item)


class FileWatcher:
    """Says when any of a set of files changed (written, replaced, removed or created) since the last look."""

    def __init__(self, paths: Iterable[Path]) -> None:
        self._stamps: dict[Path, tuple[int, int] | None] = {}
        self.watch(paths)

    def watch(self, paths: Iterable[Path]) -> None:
        """Watch `paths` from now on. A path watched before keeps the state it was last seen in, so a save made while
        the env was rebuilding is still a change; a new path is measured from its present state."""
        self._stamps = {Path(p): self._stamps[Path(p)] if Path(p) in self._stamps else _stamp(Path(p)) for p in paths}

    @property
    def paths(self) -> list[Path]:
        return list(self._stamps)

    def changed(self) -> bool:
        """Whether a file changed since the last call (or :meth:`watch`)."""
        now = {path: _stamp(path) for path in self._stamps}
        different = now != self._stamps
        self._stamps = now
        return different


def _stamp(path: Path) -> tuple[int, int] | None:
    try:
        status = path.stat()
    except OSError:
        return None
    return status.st_mtime_ns, status.st_size
