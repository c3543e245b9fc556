"""The same states render the same pixels, bit for bit, in every process: loaded or idle, on any number of threads.

Compared on the linear Combined pass (``BlenderRenderer.last_linear_pass``), where
8-bit observations hide most bits: before the fix this test guards
(``visualenv.compat.blender.sort_faces``), every fresh process rendered the pendulum's
capsules and Goalie's ball with vertex normals summed in another order, and so in
other last bits (docs/testing.md, "Deterministic rendering").
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.blender

pytest.importorskip("bpy")

REPO = Path(__file__).resolve().parents[2]

#: every primitive the spec language builds, smooth where it can be, lit so that normals show
PRIMITIVES = textwrap.dedent("""\
    id: Primitives-v0
    scene:
      objects:
        Sphere:   {primitive: sphere, radius: 0.4, location: [-1.2, 0, 0.4], smooth: true}
        Cylinder: {primitive: cylinder, radius: 0.3, depth: 0.8, location: [-0.4, 0, 0.4], smooth: true}
        Cone:     {primitive: cone, radius: 0.3, depth: 0.8, location: [0.4, 0, 0.4], smooth: true}
        Torus:    {primitive: torus, radius: 0.3, thickness: 0.1, location: [1.2, 0, 0.4], smooth: true}
        Disk:     {primitive: disk, radius: 0.3, location: [0, 0.8, 0.9], smooth: true}
        Ring:     {primitive: ring, radius: 0.3, thickness: 0.1, location: [0.8, 0.8, 0.9], smooth: true}
        Cube:     {primitive: cube, size: 0.4, location: [-0.8, 0.8, 0.9], smooth: true}
        Floor:    {primitive: plane, size: [6, 6, 1]}
        Sun:      {light: sun, strength: 3.0, rotation: [0.6, 0.2, 0.8]}
        Camera:   {camera: perspective, location: [0, -4, 2.5], look_at: [0, 0, 0.4], lens: 35}
    state:
      spin: {init: "uniform(-0.5, 0.5)"}
    actions:
      continuous:
        turn: {low: -0.2, high: 0.2}
    dynamics:
      update: {spin: spin + turn}
    actors:
      Sphere: {rotation: [0, spin, spin]}
      Torus: {rotation: [spin, 0, 0]}
    observation: {camera: Camera, resolution: [64, 64], color: rgb}
    render: {engine: cycles, preset: fast, device: cpu}
    reward: 0.0
    max_steps: 50
""")

#: renders 6 seeded steps and saves the observations and the linear passes
RENDER = textwrap.dedent("""\
    import sys
    import numpy as np
    import visualenv

    spec, threads, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    env = visualenv.make(spec, threads=threads)
    env.reset(seed=3)
    env.action_space.seed(3)
    frames, passes = [], []
    for _ in range(6):
        obs, *_ = env.step(env.action_space.sample())
        frames.append(obs)
        passes.append(env.unwrapped.renderer.last_linear_pass())
    np.savez(out, frames=np.array(frames), passes=np.array(passes))
""")

#: keeps a core busy until killed: the scheduling a loaded machine gives Blender's threads
BUSY = "while True: pass"


def _render(spec: str, threads: int, out: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-c", RENDER, spec, str(threads), str(out)],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))},
        stderr=subprocess.PIPE,
    )


def _finished(process: subprocess.Popen[bytes], out: Path) -> dict[str, np.ndarray]:
    _, err = process.communicate(timeout=240)
    assert process.returncode == 0, err.decode()[-3000:]
    with np.load(out) as saved:
        return {key: saved[key] for key in saved.files}


@pytest.mark.parametrize("spec", ["VisualInvertedPendulum-v0", "primitives"])
def test_the_same_states_render_the_same_bits_in_every_process_loaded_or_idle(spec, tmp_path):
    """Three fresh processes render the same seeded steps: one alone on every core, one on one render thread and one on
    every core, both beside a process that keeps a core busy. Their linear passes agree to the last bit."""
    if spec == "primitives":
        spec = str(tmp_path / "primitives.yaml")
        Path(spec).write_text(PRIMITIVES)
    alone = _finished(_render(spec, 0, tmp_path / "alone.npz"), tmp_path / "alone.npz")
    busy = subprocess.Popen([sys.executable, "-c", BUSY])
    try:
        runs = [
            (tmp_path / f"loaded{threads}.npz", _render(spec, threads, tmp_path / f"loaded{threads}.npz"))
            for threads in (1, 0)
        ]
        loaded = [_finished(process, out) for out, process in runs]
    finally:
        busy.kill()
        busy.wait()
    assert alone["passes"].shape[0] == 6 and alone["passes"].dtype == np.float32
    assert np.ptp(alone["passes"][..., :3]) > 0.1, "an empty image proves nothing"
    for other in loaded:
        different = np.flatnonzero((alone["passes"] != other["passes"]).reshape(6, -1).any(axis=1))
        assert different.size == 0, f"steps {different.tolist()} rendered other bits"
        np.testing.assert_array_equal(alone["frames"], other["frames"])
