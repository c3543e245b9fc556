"""Blender's own console output while a scene is built, kept aside.

Blender and its importers print to the process's file descriptors 1 and 2
(C ``printf`` and add-on ``print``): OBJ import timings, glTF errors, "Read
blend" lines. Printed as they come, they land before visualenv's one-line
error and bury it. :func:`blender_output` sends them to a temporary file
instead; the caller drops them on success and shows them, marked as
Blender's, after the error on failure (on an unexpected exception they are
printed back unchanged).
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field

from visualenv.compat.glibc import flush_c_streams

#: at most this many of Blender's lines are kept with an error
MAX_LINES = 20


@dataclass
class BlenderOutput:
    """What Blender printed inside the ``with`` block (filled in on exit)."""

    lines: list[str] = field(default_factory=list)


def _flush_all() -> None:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(AttributeError, ValueError, OSError):
            stream.flush()
    flush_c_streams()  # C stdio buffers (Blender's printf)


@contextlib.contextmanager
def blender_output() -> Iterator[BlenderOutput]:
    """Redirect file descriptors 1 and 2 to a temporary file for the block; its lines end up in ``.lines``."""
    output = BlenderOutput()
    _flush_all()
    python_text = io.StringIO()  # add-ons print to sys.stdout/sys.stderr, which need not be descriptors 1 and 2
    with (
        tempfile.TemporaryFile() as tmp,
        contextlib.redirect_stdout(python_text),
        contextlib.redirect_stderr(python_text),
    ):
        saved = os.dup(1), os.dup(2)
        os.dup2(tmp.fileno(), 1)
        os.dup2(tmp.fileno(), 2)
        failed = False
        try:
            yield output
        except BaseException:
            failed = True
            raise
        finally:
            _flush_all()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            tmp.seek(0)
            text = tmp.read().decode("utf-8", "replace") + python_text.getvalue()
            output.lines = [line.rstrip() for line in text.splitlines() if line.strip()]
            if failed and output.lines:  # an unexpected exception: give Blender's lines back as they were
                with contextlib.suppress(OSError):
                    os.write(2, ("\n".join(output.lines) + "\n").encode())


def marked(lines: list[str], said: str = "") -> list[str]:
    """Blender's lines as shown after an error: each prefixed ``blender:``, long logs cut; lines `said` already holds are left out."""
    lines = [line for line in lines if line.strip() not in said]
    shown = [f"blender: {line}" for line in lines[-MAX_LINES:]]
    if len(lines) > MAX_LINES:
        shown.insert(0, f"blender: ... ({len(lines) - MAX_LINES} earlier lines left out)")
    return shown
