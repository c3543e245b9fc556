"""Where a render's time goes: :class:`Profile`, the phase timings a renderer and a batch record when given one.

``visualenv bench`` sets ``renderer.profile`` (and a batch's ``profile``) to a Profile and reads
its lists afterwards; with ``profile`` None (the default) nothing is timed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: the phases: the batch's vectorised step, its binding values, their writes into the scene, Blender's render call
#: and the readback
PHASES = ("dynamics", "bind", "write", "render", "readback")


@dataclass
class Profile:
    """Seconds spent per phase (one entry per occurrence), appended while attached."""

    times: dict[str, list[float]] = field(default_factory=lambda: {phase: [] for phase in PHASES})
    #: when each occurrence began (``time.perf_counter()``), for the phases whose recorder says so: placing them in a
    #: step, and Blender's own events in a render call (``visualenv bench --phases``)
    starts: dict[str, list[float]] = field(default_factory=lambda: {phase: [] for phase in PHASES})

    def add(self, phase: str, seconds: float, start: float | None = None) -> None:
        """Record one occurrence of `phase` (one of :data:`PHASES`), begun at `start` where given."""
        self.times[phase].append(seconds)
        if start is not None:
            self.starts[phase].append(start)

    def clear(self) -> None:
        """Forget what was recorded (after a warm-up)."""
        for times in (*self.times.values(), *self.starts.values()):
            times.clear()
