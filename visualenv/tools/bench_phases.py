"""`visualenv bench --phases`: where a rendered step's time goes, per spec, and what each shader costs.

A step is cut at moments timed with ``time.perf_counter`` in this process: the step's start and end (here), the
renderer's writes, render calls and readbacks (its public ``profile`` hook, which records when each began), the
start of Cycles' update and each status line Blender hands ``bpy.app.handlers.render_stats``
(:mod:`visualenv.tools.render_events`). The columns therefore add up to the step. Steps alternate between recorded
and not: the render calls of the unrecorded ones say what recording costs (``hooks``), which is taken out of the
phases it fell in. Then :mod:`visualenv.tools.bench_ablation` renders copies of the scene, one shader made plain in
each, at the same states. Timings vary on a shared machine: this prints figures, it asserts nothing.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from visualenv.errors import ConfigError
from visualenv.render.profile import Profile
from visualenv.tools.bench import device_option, random_actions, run_env
from visualenv.tools.bench_ablation import PARTS, ablation
from visualenv.tools.render_events import MARKED, SYNC_PARTS, BlenderEvents, marked_call, split_call

#: the columns of a step, in its order; they add up to the step
COLUMNS = ("env", "update", "depsgraph", "sync", "bvh", "trace", "film", "readback", "rest", "hooks")

#: how each figure is obtained (printed under the table, kept in the JSON record)
HOW = {
    "step": "the env's step (wrappers included), recorded steps only; trimmed mean: the slowest tenth of steps left "
    "out, the same steps for every column",
    "env": "the step before the renderer's first write: action, physics, episode rules, binding values",
    "update": "the scene update: poses and bound properties written into Blender, camera and settings, until the "
    "render call (the renderer's profile)",
    "depsgraph": "the render call until Cycles' update starts: the operator, render_pre, Blender's depsgraph evaluation",
    "sync": "Cycles' sync, from its update's start to the first sample, less the BVH; its parts (start: until Cycles' "
    "first line; objects, lights, world, shaders, images; other) by the status line that opened each stretch "
    "(bpy.app.handlers.render_stats)",
    "bvh": "the stretches Cycles reports as 'Updating Scene BVH' (render_stats)",
    "trace": "path tracing: from Cycles' 'Sample 0/N' line to its 'Sample N/N'",
    "film": "from the last sample to the render call's end: the result written back, the in-memory copy of the "
    "pass, render_post",
    "readback": "the pass converted to the observation's bytes (the renderer's profile)",
    "rest": "the step after the readback: sensors, info, wrappers",
    "marked": "the render call cut at the marks Cycles' engine methods make (nearly free, on every step): before its "
    "update, the update, between, its render method, after it; median, for the steps with the lines and without",
    "hooks": "what recording costs, taken out of each phase for its status lines: per line, the median difference "
    "between the render calls of alternate steps with and without the handler over the lines of a call, at most the "
    "shortest stretches between two lines (10th percentile); the rest of that difference (hooks_added_ms in the "
    "record) stays where it fell",
    "floor/skybox/bodies": "the render call of a copy of the scene with that shader replaced by a plain diffuse (a "
    "one-colour world for the skybox), minus a control copy's, median over the same states, copies rendered in "
    "turn (negative: plain is cheaper); '-' where the scene has no such part",
}


def _spans(profile: Profile, phase: str, start: float, end: float) -> list[tuple[float, float]]:
    """(start, end) of each occurrence of `phase` that began within [start, end]."""
    return [(s, s + d) for s, d in zip(profile.starts[phase], profile.times[phase]) if start <= s <= end]


def split_step(
    start: float, end: float, profile: Profile, events: list[tuple[float, str]]
) -> tuple[dict[str, float], dict[str, int], dict[str, float]]:
    """One step's seconds per column (sync by part, ``sync.<part>``), its status lines per phase and its render
    calls' seconds per status line (hooks included)."""
    writes = _spans(profile, "write", start, end)
    renders = _spans(profile, "render", start, end)
    reads = _spans(profile, "readback", start, end)
    seconds = dict.fromkeys(("env", "update", "readback", "rest", "hooks"), 0.0)
    lines: dict[str, int] = {}
    labels: dict[str, float] = {}
    here = writes[0][0] if writes else renders[0][0] if renders else end
    seconds["env"] = here - start
    for (call_start, call_end), read in zip(renders, reads):
        seconds["update"] += call_start - here
        split = split_call(call_start, call_end, events)
        for label, value in split.labels.items():
            labels[label] = labels.get(label, 0.0) + value
        for phase, value in split.seconds.items():
            seconds[phase] = seconds.get(phase, 0.0) + value
        for phase, count in split.events.items():
            lines[phase] = lines.get(phase, 0) + count
        seconds["readback"] += read[1] - read[0]
        here = read[1]
    seconds["rest"] = end - here
    return seconds, lines, labels


def bench_phases(
    spec: str,
    steps: int = 200,
    *,
    seed: int = 0,
    warmup: int = 20,
    ablation_steps: int | None = None,
    readback: str = "auto",
    threads: int | None = None,
    device: str | None = None,
    trust_code: bool = False,
) -> dict[str, Any]:
    """The phase record of `spec`: `steps` steps (every other one recorded), then the shader ablation over
    `ablation_steps` states (default: half the steps)."""
    from visualenv.env.make import make
    from visualenv.render.blender.scene.user_file import render_layer

    options: dict[str, Any] = {"readback": readback, **device_option(device, trust_code)}
    if threads:
        options["threads"] = threads
    env = make(spec, **options)
    base: Any = env.unwrapped  # the VisualEnv under the wrappers
    try:
        if not base.uses_camera:
            raise ConfigError(f"{spec}: bench --phases splits a render's time, and this env renders nothing")
        n_ablation = max(1, steps // 2) if ablation_steps is None else ablation_steps
        actions = random_actions(env, warmup + steps + n_ablation, seed)
        run_env(env, actions[:warmup], seed)
        renderer = base.renderer
        scene = renderer.scene
        if scene.render.engine != "CYCLES":
            raise ConfigError(
                f"{spec}: bench --phases splits Cycles' render, and this spec renders with {scene.render.engine}"
            )
        profile, events = Profile(), BlenderEvents()
        windows: list[tuple[float, float, bool]] = []
        renderer.profile = profile
        try:
            env.reset(seed=seed + 1)
            for i, action in enumerate(actions[warmup : warmup + steps]):
                recorded = events.lines = i % 2 == 0
                with events:
                    start = time.perf_counter()
                    _, _, terminated, truncated, _ = env.step(action)
                    windows.append((start, time.perf_counter(), recorded))
                if terminated or truncated:
                    env.reset()
        finally:
            renderer.profile = None
        record = _summary(windows, profile, events.events)
        record["marked_ms"] = _marked(windows, profile, events.marks)
        record.update(spec=str(spec), id=base.program.spec.id, pixels=_pixels(renderer))
        rest = actions[warmup + steps :]

        def step(i: int) -> None:
            _, _, terminated, truncated, _ = env.step(rest[i])
            if terminated or truncated:
                env.reset()

        record["ablation"] = ablation(scene, render_layer(scene), n_ablation, step)
        record["how"] = HOW
        return record
    finally:
        env.close()


def _pixels(renderer: Any) -> str:
    return ", ".join(f"{v.resolution[0]}x{v.resolution[1]} {v.color}" for v in renderer.plan.views.values())


def _marked(
    windows: list[tuple[float, float, bool]], profile: Profile, marks: list[tuple[float, str]]
) -> dict[str, dict[str, float]]:
    """The render calls cut at Cycles' marks alone, median per step (ms), for the steps with the lines and without."""
    out: dict[str, dict[str, float]] = {}
    for recorded, key in ((True, "with_lines"), (False, "without_lines")):
        rows = []
        for start, end, r in windows:
            if r is not recorded:
                continue
            cut = [marked_call(s, e, marks) for s, e in _spans(profile, "render", start, end)]
            if cut and all(c is not None for c in cut):
                rows.append({name: sum(c[name] for c in cut if c is not None) for name in MARKED})
        out[key] = {name: 1000 * float(np.median([row[name] for row in rows])) if rows else 0.0 for name in MARKED}
    return out


def _summary(windows: list[tuple[float, float, bool]], profile: Profile, events: list[tuple[float, str]]) -> dict:
    """The columns' trimmed means over the recorded steps, with the recording's cost taken out (ms)."""
    splits = [split_step(s, e, profile, events if recorded else []) for s, e, recorded in windows]
    outside = ("env", "update", "readback", "rest", "hooks")
    calls = [sum(v for k, v in seconds.items() if k not in outside) for seconds, _, _ in splits]
    recorded = [i for i, (_, _, r) in enumerate(windows) if r]
    paired = [calls[i] - calls[i + 1] for i in recorded if i + 1 < len(splits)]
    lines_per_step = float(np.mean([sum(splits[i][1].values()) for i in recorded])) if recorded else 0.0
    added = max(0.0, float(np.median(paired))) if paired else 0.0
    # a line's handler cannot cost more than the shortest stretches between two lines, which hold little else
    times = np.array([t for t, _ in events])
    stretches = [d for s, e, r in windows if r for d in np.diff(times[(times >= s) & (times <= e)]) if d > 0]
    shortest = float(np.percentile(stretches, 10)) if stretches else 0.0
    per_line = min(added / lines_per_step, shortest) if lines_per_step else 0.0
    rows = []
    for i in recorded:
        seconds, lines, labels = splits[i]
        for phase, count in lines.items():
            cut = min(seconds[phase], count * per_line)
            seconds[phase] -= cut
            seconds["hooks"] += cut
        rows.append((windows[i][1] - windows[i][0], seconds, labels))
    steps = np.array([step for step, _, _ in rows])
    kept = [row for row in rows if row[0] <= np.percentile(steps, 90)] if len(rows) >= 10 else rows

    def mean(key: str, labelled: bool = False) -> float:
        values = [(row[2] if labelled else row[1]).get(key, 0.0) for row in kept]
        return 1000 * float(np.mean(values)) if values else 0.0

    columns = {key: mean(key) for key in COLUMNS if key != "sync"}
    sync = {part: mean(f"sync.{part}") for part in SYNC_PARTS}
    columns["sync"] = sum(sync.values())
    names = {label for row in kept for label in row[2]}
    longest = sorted(((mean(label, labelled=True), label) for label in names), reverse=True)
    unrecorded = [e - s for s, e, r in windows if not r]
    return {
        "steps": len(rows),
        "steps_kept": len(kept),
        "step_ms": 1000 * float(np.mean([row[0] for row in kept])) if kept else 0.0,
        "step_unrecorded_ms_median": 1000 * float(np.median(unrecorded)) if unrecorded else 0.0,
        "columns_ms": {key: columns[key] for key in COLUMNS},
        "sync_ms": sync,
        "status_lines_ms": {label: value for value, label in longest},
        "status_lines_per_step": lines_per_step,
        "hooks_us_per_line": 1e6 * per_line,
        "hooks_added_ms": 1000 * added,
    }


def table(records: list[dict[str, Any]]) -> list[str]:
    """The records as a Markdown table, one row per spec (ms), then sync's parts, then how each figure is obtained."""
    head = ["spec", "pixels", "step", *COLUMNS, *PARTS]
    out = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for r in records:
        parts = r["ablation"]["parts"]
        cells = [r["id"], r["pixels"], f"{r['step_ms']:.2f}", *(f"{r['columns_ms'][c]:.2f}" for c in COLUMNS)]
        cells += [f"{parts[p]['call_ms']:+.2f}" if p in parts else "-" for p in PARTS]
        out.append("| " + " | ".join(cells) + " |")
    out += [
        "",
        "sync by part (ms):",
        "",
        "| spec | " + " | ".join(SYNC_PARTS) + " |",
        "|" + " --- |" * (1 + len(SYNC_PARTS)),
    ]
    for r in records:
        out.append(f"| {r['id']} | " + " | ".join(f"{r['sync_ms'][p]:.2f}" for p in SYNC_PARTS) + " |")
    out += [
        "",
        "what recording added to a render call (the median over pairs of alternate steps), and how much of it hooks holds:",
    ]
    for r in records:
        out.append(
            f"  {r['id']}: {r['hooks_added_ms']:.2f} ms for {r['status_lines_per_step']:.0f} lines; "
            f"{r['columns_ms']['hooks']:.2f} ms taken out ({r['hooks_us_per_line']:.1f} us a line), the rest left in the "
            f"phases; unrecorded step {r['step_unrecorded_ms_median']:.2f} ms (median)"
        )
    out += [
        "",
        "the render call cut at Cycles' marks alone (median ms; "
        + ", ".join(MARKED)
        + "), without the lines / with them:",
    ]
    for r in records:
        without, lines = r["marked_ms"]["without_lines"], r["marked_ms"]["with_lines"]
        out.append(f"  {r['id']}: " + "; ".join(f"{name} {without[name]:.2f} / {lines[name]:.2f}" for name in MARKED))
    out += ["", "the render call's longest stretches, by the status line that opened them (ms, hooks included):"]
    for r in records:
        top = list(r["status_lines_ms"].items())[:6]
        out.append(f"  {r['id']}: " + "; ".join(f"{label} {value:.2f}" for label, value in top))
    out += ["", "ms per step; the columns add up to the step. How each figure is obtained:"]
    out += [f"  {key}: {how}" for key, how in HOW.items()]
    return out
