"""Blender's own account of a render call, for ``visualenv bench --phases``: its status lines, timed as they come.

While recording, :class:`BlenderEvents` keeps ``(time.perf_counter(), text)`` for every status line Blender hands
``bpy.app.handlers.render_stats`` (Cycles names each step it takes: "Synchronizing object | cart", "Updating Scene
BVH | Building BVH", "Sample 0/1", "Finished") and for the start of Cycles' ``update`` (where Blender's depsgraph
evaluation ends and Cycles' sync of its data begins: :func:`visualenv.compat.blender.mark_cycles_calls`).
:func:`split_call` then gives each stretch of a render call to the phase of the line that opened it.
"""

from __future__ import annotations

import bisect
import re
import time
from dataclasses import dataclass, field
from typing import Any

#: the phases of Blender's render call, in the order a render goes through them
CALL_PHASES = ("depsgraph", "sync", "bvh", "trace", "film")
#: the parts of Cycles' sync its status lines name
#: (``start``: from Cycles' update until its first line, where it reads the view layer, integrator, film, shaders and
#: world without naming a step; ``other``: lines named for none of the rest)
SYNC_PARTS = ("start", "objects", "lights", "world", "shaders", "images", "other")

#: the start of Cycles' update (a mark, not a status line)
UPDATE_MARK = "<cycles update>"

#: a status line's step (its first field that is not Blender's memory or time figures) -> its phase; first match wins
_STEPS = (
    ("Updating Scene BVH", "bvh"),
    ("Updating Geometry BVH", "bvh"),
    ("Building BVH", "bvh"),
    ("Sample", "trace"),
    ("Path Tracing", "trace"),
    ("Rendering", "trace"),
    ("Denoising", "trace"),
    ("Finished", "film"),
    ("Cancel", "film"),
    ("Synchronizing object", "sync.objects"),
    ("Updating Object", "sync.objects"),
    ("Updating Mesh", "sync.objects"),
    ("Updating Geometry", "sync.objects"),
    ("Updating Primitive", "sync.objects"),
    ("Updating Particle", "sync.objects"),
    ("Updating Hair", "sync.objects"),
    ("Updating Point", "sync.objects"),
    ("Updating Procedural", "sync.objects"),
    ("Updating Attributes", "sync.objects"),
    ("Updating Lights", "sync.lights"),
    ("Updating Background", "sync.world"),
    ("Updating Shaders", "sync.shaders"),
    ("Updating Images", "sync.images"),
)
_FIGURES = ("Fra:", "Mem:", "Time:", "Remaining:", "Peak", "Sce:", "Scene:")
_SAMPLE = re.compile(r"Sample (\d+)/(\d+)")


def step_of(text: str) -> str:
    """The step a status line names ("Updating Lights" of "Mem: 1M | Updating Lights | Computing tree")."""
    for part in text.split(" | "):
        part = part.strip()
        if part and not part.startswith(_FIGURES):
            return part
    return ""


def label_of(text: str) -> str:
    """A status line less Blender's figures ("Updating Lights | Computing tree")."""
    if text == UPDATE_MARK:
        return "(Cycles' update, before its first line)"
    parts = [part.strip() for part in text.split(" | ")]
    return " | ".join(part for part in parts if part and not part.startswith(_FIGURES))


def phase_of(text: str) -> str:
    """The phase (one of :data:`CALL_PHASES`, ``sync.<part>`` for sync) a status line opens; "" for one it does not
    name. The last sample's line ("Sample 1/1") opens the film: what follows is the result written back."""
    if text == UPDATE_MARK:
        return "sync.start"
    step = step_of(text)
    sample = _SAMPLE.match(step)
    if sample is not None and int(sample.group(1)) >= int(sample.group(2)) > 0:
        return "film"
    return next((phase for key, phase in _STEPS if step.startswith(key)), "")


@dataclass
class CallSplit:
    """One render call's seconds per phase (``sync.<part>`` keys for sync's parts), its events per phase, and its
    seconds per status line (``labels``: the line less Blender's figures)."""

    seconds: dict[str, float] = field(default_factory=dict)
    events: dict[str, int] = field(default_factory=dict)
    labels: dict[str, float] = field(default_factory=dict)

    def total(self, phase: str) -> float:
        """A phase's seconds, sync's parts summed."""
        return sum(v for k, v in self.seconds.items() if k == phase or k.startswith(phase + "."))


def split_call(start: float, end: float, events: list[tuple[float, str]]) -> CallSplit:
    """The render call from `start` to `end` (perf_counter seconds) split at the events in it (sorted by time).

    Before Cycles' update starts (or its first line): ``depsgraph`` (the operator, ``render_pre``, Blender's depsgraph
    evaluation). From then on each stretch belongs to the phase of the line that opened it; a line no phase names
    continues sync before the first sample and the film after it.
    """
    split = CallSplit({p: 0.0 for p in ("depsgraph", "bvh", "trace", "film")} | {f"sync.{p}": 0.0 for p in SYNC_PARTS})
    times = [t for t, _ in events]
    inside = events[bisect.bisect_left(times, start) : bisect.bisect_right(times, end)]
    here, phase, label, traced = start, "depsgraph", "(before Cycles' update)", False
    for moment, text in [*inside, (end, "")]:
        split.seconds[phase] += moment - here
        split.labels[label] = split.labels.get(label, 0.0) + moment - here
        if not text:
            break
        named = phase_of(text)
        traced = traced or named in ("trace", "film")
        phase = named or ("film" if traced else "sync.other")
        label = label_of(text)
        split.events[phase] = split.events.get(phase, 0) + 1
        here = moment
    return split


class BlenderEvents:
    """Records Blender's status lines (where `lines`) and the moments Cycles' engine marks (its update's and render's
    starts and ends, into :attr:`marks`; the update's start also into :attr:`events`) while entered
    (``with events: render()``). The marks cost next to nothing (Python calls on the thread already running Python);
    the lines are a Python handler Blender calls from Cycles' threads, which costs each render call some time."""

    def __init__(self) -> None:
        self.events: list[tuple[float, str]] = []
        self.marks: list[tuple[float, str]] = []
        self.lines = True
        self._stop: Any = None

    def line(self, text: str, *args: Any) -> None:
        """The ``render_stats`` handler: one status line, timed."""
        self.events.append((time.perf_counter(), text))

    def mark(self, moment: str) -> None:
        """Cycles' engine calls this at its update's and render's starts and ends (:data:`~visualenv.compat.blender.CYCLES_MARKS`)."""
        now = time.perf_counter()
        self.marks.append((now, moment))
        if moment == "update":
            self.events.append((now, UPDATE_MARK))

    def clear(self) -> None:
        self.events.clear()
        self.marks.clear()

    def __enter__(self) -> BlenderEvents:
        import bpy

        from visualenv.compat.blender import mark_cycles_calls

        if self.lines:
            bpy.app.handlers.render_stats.append(self.line)
        self._stop = mark_cycles_calls(self.mark)
        return self

    def __exit__(self, *exc: object) -> None:
        import bpy

        if self.line in bpy.app.handlers.render_stats:
            bpy.app.handlers.render_stats.remove(self.line)
        if self._stop is not None:
            self._stop()
            self._stop = None


#: the render call cut at Cycles' marks alone: Blender before Cycles' update, the update (Blender's data read into
#: Cycles), Blender between it and the render, Cycles' render method (device update, BVH, tracing, the result written
#: back, the in-memory copy), Blender after it
MARKED = ("before_update", "cycles_update", "between", "cycles_render", "after_render")


def marked_call(start: float, end: float, marks: list[tuple[float, str]]) -> dict[str, float] | None:
    """The call from `start` to `end` cut at the first of each Cycles mark in it; None where one is missing."""
    inside = {}
    for moment, name in marks:
        if start <= moment <= end and name not in inside:
            inside[name] = moment
    if not all(name in inside for name in ("update", "update_end", "render", "render_end")):
        return None
    cuts = [start, inside["update"], inside["update_end"], inside["render"], inside["render_end"], end]
    return {name: b - a for name, a, b in zip(MARKED, cuts[:-1], cuts[1:])}
