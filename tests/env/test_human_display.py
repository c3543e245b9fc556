"""render_mode="human" reaches its display through the env layer's hook (visualenv.env.human), not by importing the
viewer: a registered fake display gets every reset, step and close of an env and a batch (fake renderers, no Blender),
none registered is a clear error, and ``import visualenv`` registers the viewer's page without loading it.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

import numpy as np
import pytest

from visualenv import VisualEnv, load_spec_text
from visualenv.env.batch import BatchedVectorEnv
from visualenv.env.human import HumanDisplay, grid, open_human_display, register_human_display
from visualenv.errors import VisualEnvError
from visualenv.render.base import RenderPlan, Renderer, RendererOptions
from visualenv.render.frames import Frames

REPO = Path(__file__).resolve().parents[2]

SPEC = """
id: Mover-v0
state:
  x: {init: 0.0}
actions:
  discrete:
    - {}
    - {move: 1}
dynamics:
  update: {x: x + move}
reward: move
max_steps: 5
scene:
  objects:
    ball: {primitive: sphere, location: [0, 0, 0]}
    cam: {camera: perspective, location: [0, -5, 0]}
actors:
  ball: {location: "[x, 0, 2 * x]"}
observation:
  camera: cam
  resolution: [8, 6]
  color: grayscale
"""


def _size(plan: RenderPlan) -> tuple[int, int]:
    width, height = next(iter(plan.views.values())).resolution
    return height, width


class FakeRenderer(Renderer):
    """One env's frames: the first binding value in every pixel."""

    def __init__(self, plan: RenderPlan, options: RendererOptions) -> None:
        self.plan = plan

    def render(self, frames: Frames) -> np.ndarray:
        return np.full((frames.n, *_size(self.plan), 1), frames.values[0][0], np.uint8)

    def render_view(self, frames: Frames) -> np.ndarray:
        return np.full((frames.n, 4, 4, 3), 7, np.uint8)

    def close(self) -> None:
        pass


class FakeBatchRenderer(FakeRenderer):
    """A batch's frames: env k's tile holds k + 1."""

    def __init__(self, plan: RenderPlan, options: RendererOptions, num_envs: int) -> None:
        self.plan, self.n = plan, num_envs

    def render(self, frames: Frames) -> np.ndarray:
        chosen = range(self.n) if frames.envs is None else frames.envs
        return np.stack([np.full((*_size(self.plan), 1), k + 1, np.uint8) for k in chosen])


def fake_env() -> VisualEnv:
    loaded = load_spec_text(textwrap.dedent(SPEC), "t.yaml")
    return VisualEnv(loaded, backend=f"{__name__}:FakeRenderer", render_mode="human")


class RecordingDisplay:
    """A display that keeps what it was shown."""

    def __init__(self) -> None:
        self.shown: list[tuple[str, Any, dict[str, Any], Callable[[], np.ndarray] | None]] = []
        self.closed = False

    def show(
        self, title: str, observation: Any, values: Mapping[str, Any], view: Callable[[], np.ndarray] | None = None
    ) -> None:
        self.shown.append((title, observation, dict(values), view))

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def displays() -> Iterator[list[RecordingDisplay]]:
    """Every display opened while the test runs; the viewer's factory is back afterwards."""
    opened: list[RecordingDisplay] = []

    def factory() -> HumanDisplay:
        opened.append(RecordingDisplay())
        return opened[-1]

    previous = register_human_display(factory)
    try:
        yield opened
    finally:
        register_human_display(previous)


def test_an_env_in_human_mode_shows_each_reset_and_step_on_the_registered_display(displays):
    env = fake_env()
    assert displays == []  # opened by the first step shown, not by the env
    obs, _ = env.reset(seed=0)
    env.step(1)
    obs, *_ = env.step(1)
    assert env.render() is None
    [display] = displays
    assert {title for title, *_ in display.shown} == {"Mover-v0"}
    assert [values["reward"] for _, _, values, _ in display.shown] == [None, 1, 1]  # the reset, then the steps
    title, observation, values, view = display.shown[-1]
    np.testing.assert_array_equal(observation, obs)
    assert observation[0, 0, 0] == 2 and values["state"]["x"] == 2.0
    assert view is not None and view().shape == (4, 4, 3)  # the view, rendered only when the display calls it
    env.close()
    assert display.closed


def test_a_batch_in_human_mode_shows_the_grid_of_its_observations(displays):
    loaded = load_spec_text(textwrap.dedent(SPEC), "t.yaml")
    batch = BatchedVectorEnv(loaded, 4, render_mode="human", backend=f"{__name__}:FakeBatchRenderer")
    obs, _ = batch.reset(seed=0)
    obs, *_ = batch.step(np.array([1, 0, 1, 0]))
    [display] = displays
    title, pictures, values, view = display.shown[-1]
    assert len(display.shown) == 2 and title == "Mover-v0" and view is None
    np.testing.assert_array_equal(pictures, grid(obs))
    assert pictures.shape == (2 * 7 - 1, 2 * 9 - 1, 1) and values["envs"] == 4 and values["steps"] == 1
    batch.close()
    assert display.closed


def test_without_a_registered_display_human_mode_says_how_to_get_one():
    previous = register_human_display(None)
    try:
        with pytest.raises(VisualEnvError, match=r"none is registered.*import visualenv.*register_human_display"):
            open_human_display()
        env = fake_env()
        with pytest.raises(VisualEnvError, match="render_mode='human' needs a display"):
            env.reset(seed=0)
        env.close()
    finally:
        register_human_display(previous)


def test_import_visualenv_registers_the_viewers_page_without_loading_it():
    from visualenv import viewer

    registered = register_human_display(None)
    register_human_display(registered)
    assert registered is viewer.open_display
    code = (
        "import sys, visualenv; from visualenv.env.human import register_human_display as hook; "
        "from visualenv import viewer; registered = hook(None); hook(registered); "
        "assert registered is viewer.open_display, registered; "
        "assert not {'werkzeug', 'visualenv.viewer.human', 'visualenv.viewer.board'} & set(sys.modules)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert result.returncode == 0, result.stderr
