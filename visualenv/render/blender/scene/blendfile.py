"""Read a user's .blend in a child process first, so a file that crashes Blender cannot take this process down.

One reader process (``python -m visualenv.render.blender.scene.describe``) per process serves every
request and is started again after a crash. Its answer (:func:`describe`) lists what the file holds
(scenes, cameras, lights, meshes, materials, animation, the settings a spec overrides) for
``visualenv inspect`` and ``init``, and what is missing (linked libraries, image files) for the
renderer's checks. Answers are remembered per file path, size and modification time.
"""

from __future__ import annotations

import atexit
import json
import os
import select
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from visualenv.errors import VisualEnvError

#: seconds one file may take to read before the reader is stopped
READ_TIMEOUT = 120.0


class BlendReadError(VisualEnvError):
    """Blender could not read a .blend file (it crashed, hung or refused it)."""


class _Reader:
    """The reader process: one JSON line in, one out; it exits by itself when idle (IDLE_EXIT)."""

    def __init__(self, command: list[str] | None = None) -> None:
        self.command = command or [sys.executable, "-m", "visualenv.render.blender.scene.describe"]
        self.proc: subprocess.Popen[str] | None = None
        self.owner = os.getpid()  # a forked process starts its own reader rather than share the pipes

    def start(self) -> subprocess.Popen[str]:
        if self.proc is None or self.proc.poll() is not None or self.owner != os.getpid():
            self.owner = os.getpid()
            env = dict(os.environ)
            root = str(Path(__file__).resolve().parents[3])  # the folder holding the visualenv package
            env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
            self.proc = subprocess.Popen(
                self.command,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
                encoding="utf-8",
                env=env,
            )
        return self.proc

    def ask(self, path: str, timeout: float) -> dict[str, Any]:
        for attempt in range(2):
            if self.proc is not None and self.proc.poll() == 0:
                self.proc = None  # it stopped itself after an idle while
            proc = self.start()
            assert proc.stdin is not None and proc.stdout is not None
            try:
                proc.stdin.write(json.dumps({"path": path}) + "\n")
                proc.stdin.flush()
            except BrokenPipeError:
                pass
            ready, _, _ = select.select([proc.stdout], [], [], timeout)
            line = proc.stdout.readline() if ready else ""
            if line:
                return json.loads(line)
            if not ready:
                proc.kill()
            code = proc.wait()
            self.proc = None
            if not ready:
                raise BlendReadError(f"Blender did not finish reading {path} in {timeout:.0f} s")
            if code == 0 and attempt == 0:
                continue  # it went idle just as the request came: ask a new one
            named = code < 0 and -code in {s.value for s in signal.Signals}
            how = f"signal {signal.Signals(-code).name}" if named else f"exit status {code}"
            raise BlendReadError(
                f"Blender crashed ({how}) while reading {path}: open it in Blender and save it again "
                "(File > Save As), or use a file saved by another Blender version"
            )
        raise AssertionError("unreachable")  # pragma: no cover

    def close(self) -> None:
        proc, self.proc = self.proc, None
        if proc is None or self.owner != os.getpid():
            return
        for stream in (proc.stdin, proc.stdout):
            if stream is not None:
                stream.close()  # the reader ends at the end of its input
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def is_blend_file(path: str | Path) -> bool:
    """Whether the file starts as a .blend does (Blender's header, or zstd/gzip compression)."""
    with open(path, "rb") as f:
        magic = f.read(7)
    return magic.startswith(b"BLENDER") or magic[:4] == b"\x28\xb5\x2f\xfd" or magic[:2] == b"\x1f\x8b"


_reader = _Reader()
atexit.register(lambda: _reader.close())
_answers: dict[tuple[str, int, int], dict[str, Any]] = {}


def describe(path: str | Path, *, timeout: float = READ_TIMEOUT) -> dict[str, Any]:
    """What the .blend at `path` holds (see :mod:`visualenv.render.blender.scene.describe`); BlendReadError if Blender cannot read it."""
    path = str(Path(path).resolve())
    stat = os.stat(path)
    key = (path, stat.st_size, stat.st_mtime_ns)
    if key not in _answers:
        answer = _reader.ask(path, timeout)
        if "error" in answer:
            raise BlendReadError(f"cannot read {path} as a .blend file: {answer['error']}")
        _answers[key] = answer["ok"]
    return _answers[key]
