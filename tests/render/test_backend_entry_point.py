"""The env finds its renderer by an entry-point string: a fake backend checks the logic around it without Blender."""

import pickle
import textwrap
from typing import Any

import numpy as np
import pytest

from visualenv import VisualEnv, load_spec_text
from visualenv.errors import SpecError
from visualenv.render.base import RenderPlan, Renderer, RendererOptions, load_backend
from visualenv.render.frames import Frames

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
reward: 0
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


class FakeRenderer(Renderer):
    """Draws the binding values into the first pixels, so a test can read them back."""

    made: list["FakeRenderer"] = []

    def __init__(self, plan: RenderPlan, options: RendererOptions) -> None:
        self.plan = plan
        self.options = options
        self.closed = False
        FakeRenderer.made.append(self)

    def render(self, frames: Frames) -> np.ndarray:
        view = next(iter(self.plan.views.values()))
        width, height = view.resolution
        images = np.zeros((frames.n, height, width, 1), np.uint8)
        for image, values in zip(images, frames.values):
            image.flat[: len(values)] = values
        return images

    def render_view(self, frames: Frames) -> np.ndarray:
        return np.zeros((frames.n, 4, 4, 3), np.uint8)

    def close(self) -> None:
        self.closed = True


BACKEND = f"{__name__}:FakeRenderer"


def fake_env(**kwargs: Any) -> VisualEnv:
    return VisualEnv(load_spec_text(textwrap.dedent(SPEC), "t.yaml"), backend=BACKEND, **kwargs)


def test_the_backend_gets_the_plan_the_options_and_the_binding_values():
    FakeRenderer.made.clear()
    env = fake_env(renderer_options={"samples": 2})
    obs, _ = env.reset(seed=0)
    env.step(1)
    obs, *_ = env.step(1)
    renderer = FakeRenderer.made[-1]
    assert [(t.object, t.property, t.size) for t in renderer.plan.bindings] == [("ball", "location", 3)]
    assert renderer.options == RendererOptions(samples=2)
    assert renderer.plan.settings.samples == 2  # merged into the plan's settings once, before the backend sees them
    assert obs.shape == (6, 8, 1) and obs.flat[:3].tolist() == [2, 0, 4]
    env.close()
    assert renderer.closed


def test_the_backend_survives_pickling():
    FakeRenderer.made.clear()
    env = pickle.loads(pickle.dumps(fake_env()))
    env.reset(seed=0)
    assert isinstance(env.renderer, FakeRenderer)


def test_a_backend_that_is_not_module_colon_attribute_is_refused():
    with pytest.raises(ValueError, match="module:attribute"):
        load_backend("visualenv.render.blender")


def test_renderer_options_are_checked_when_made():
    with pytest.raises(
        TypeError, match="unknown renderer option.s. colour: use engine, samples, device, threads, noise, readback"
    ):
        fake_env(renderer_options={"colour": 1})
    with pytest.raises(ValueError, match="unknown readback 'gpu'"):
        RendererOptions(readback="gpu")  # type: ignore[arg-type]
    with pytest.raises(
        SpecError, match=r"visualenv.make\(\): samples: expected a value greater than or equal to 1, got 0"
    ):
        fake_env(renderer_options={"samples": 0})
