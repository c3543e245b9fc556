"""visualenv.make() options are checked with the spec's own models and messages.

An option overrides a spec field (``device``, ``threads``, ``samples``,
``engine``) or adds a wrapper (``frame_stack``, ``grayscale``, ``resize``);
a value the spec would refuse is refused at ``make()``, located at
``visualenv.make()``, never accepted silently. State-only envs: no Blender.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import visualenv
from visualenv.errors import SpecError

pytestmark = pytest.mark.blender

ENV = "VisualCartPole-v0"


def _refusal(**options) -> str:
    with pytest.raises(SpecError) as caught:
        visualenv.make(ENV, render=False, **options)
    assert len(caught.value.diagnostics) == 1, caught.value
    return str(caught.value)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"device": "tpu"}, "visualenv.make(): device: expected one of 'cpu', 'gpu' or 'auto', got 'tpu'"),
        ({"threads": -1}, "visualenv.make(): threads: expected a value greater than or equal to 0, got -1"),
        ({"samples": 0}, "visualenv.make(): samples: expected a value greater than or equal to 1, got 0"),
        ({"frame_stack": -1}, "visualenv.make(): frame_stack: expected a value greater than or equal to 1, got -1"),
        ({"resize": "64"}, "visualenv.make(): resize: expected a tuple, got text '64'"),
        ({"resize": (64, "64")}, "visualenv.make(): resize[1]: expected an integer, got text '64'"),
        (
            {"engine": "blender"},
            "visualenv.make(): engine: expected one of 'cycles', 'workbench' or 'eevee', got 'blender'",
        ),
        ({"threads": True}, "visualenv.make(): threads: expected an integer, got a boolean True"),
        ({"frame_stack": 2.0}, "visualenv.make(): frame_stack: expected an integer, got a number 2.0"),
        ({"render": "yes"}, "visualenv.make(): render: expected a boolean, got text 'yes'"),
        ({"noise": "loud"}, "visualenv.make(): noise: expected one of 'independent' or 'shared', got 'loud'"),
    ],
)
def test_a_bad_option_is_refused_like_the_same_value_in_a_spec(options: dict, message: str):
    with pytest.raises(SpecError) as caught:
        visualenv.make(ENV, **options)
    assert str(caught.value).startswith(message), str(caught.value)


@settings(max_examples=30, deadline=None)
@given(st.integers(-1000, 1000))
def test_threads_follow_the_spec_range(threads: int):
    if 0 <= threads <= 256:
        from visualenv.spec.options import check_make_options

        check_make_options(threads=threads)
    else:
        assert "visualenv.make(): threads: expected a value" in _refusal(threads=threads)


def test_good_options_are_accepted():
    env = visualenv.make(
        ENV, render=False, device="cpu", threads=1, samples=2, engine="cycles", params={"masscart": 2.0}
    )
    assert env.unwrapped.program.params["masscart"] == 2.0


@pytest.mark.blender
@pytest.mark.parametrize(
    "options, engine, samples, threads",
    [
        ({"device": "cpu", "threads": 1, "samples": 2, "engine": "cycles"}, "CYCLES", 2, 1),
        ({"threads": 2, "samples": 3}, "CYCLES", 3, 2),
        ({"engine": "workbench"}, "BLENDER_WORKBENCH", None, None),
    ],
)
def test_render_options_reach_blenders_scene(options, engine, samples, threads):
    """device, threads, samples and engine replace the spec's values in the scene Blender renders."""
    env = visualenv.make(ENV, **options)
    try:
        env.reset(seed=0)
        scene = env.unwrapped.renderer.scene
        assert scene.render.engine == engine
        if engine == "CYCLES":
            assert scene.cycles.device == "CPU" and scene.cycles.samples == samples
            assert scene.render.threads_mode == "FIXED" and scene.render.threads == threads
    finally:
        env.close()


@pytest.mark.parametrize(
    "value, message",
    [
        ("abc", "unknown name 'abc'"),
        ("1 / 0", "division by zero"),
    ],
)
def test_a_bad_params_override_is_blamed_on_the_override(value: str, message: str):
    text = _refusal(params={"masscart": value})
    assert text.startswith("visualenv.make(): params.masscart: ") and message in text, text
    assert "visual_cartpole.yaml" not in text


def test_an_unknown_params_override_is_blamed_on_the_override():
    text = _refusal(params={"mascart": 1.0})
    assert text.startswith(
        "visualenv.make(): params.mascart: unknown parameter override 'mascart' (did you mean 'masscart'?"
    )
