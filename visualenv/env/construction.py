"""What one env and a batch both make of their keywords: the program, whether a camera renders, the episode's length
and the cameras' sensors. Written once, so that env i of a batch is the env ``visualenv.make`` gives."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from gymnasium import spaces

from visualenv.compiler.program import Program, compile_spec
from visualenv.compiler.render_plan import views_plan
from visualenv.env.episode import step_limit
from visualenv.env.registration import resolve
from visualenv.compiler.render_plan import to_plan
from visualenv.errors import Diagnostic, SpecError
from visualenv.render.distractions import EpisodeDistractions
from visualenv.render.sensor import SensorModel, sensor_models
from visualenv.render.videos import VideoFolderError
from visualenv.spec.models import Distractions
from visualenv.spec.options import WHERE
from visualenv.spec.loader import LoadedSpec, load_spec
from visualenv.spec.view_models import Observation


def program_for(
    spec: str | os.PathLike[str] | LoadedSpec | Program, params: Mapping[str, Any] | None, trust_code: bool
) -> Program:
    """The compiled program of a spec file, build folder, id, loaded spec or program, with `params` overridden; its
    ``dynamics.python`` imported only with `trust_code` (a Program compiled with consent carries it: docs/security.md).
    """
    if isinstance(spec, Program):
        program = spec if not params else compile_spec(spec.loaded, params, trust_code=trust_code or spec.trust_code)
    else:
        loaded = spec if isinstance(spec, LoadedSpec) else load_spec(resolve(spec))
        program = compile_spec(loaded, params, trust_code=trust_code)
    program.check_code_consent()
    return program


def uses_camera(program: Program, render: bool | None) -> bool:
    """Whether observations are rendered: the spec has a camera and ``render`` is not False (True without one is an error)."""
    observation = program.spec.observation
    if render and observation is None:
        message = "render=True needs an 'observation' section (a camera) in the spec"
        raise SpecError([program.loaded.source.diagnostic((), message)])
    return observation is not None and render is not False


def episode_distractions(program: Program, settings: Distractions, optioned: bool) -> EpisodeDistractions:
    """An env's distractions across episodes; a folder of background videos that is missing or lacks the level's
    videos is a SpecError at the field that names it: the spec's line, or make()'s option where `optioned`."""
    try:
        return EpisodeDistractions(to_plan(settings))
    except VideoFolderError as exc:
        path = ("distractions", "background", "videos")
        if optioned:
            raise SpecError([Diagnostic(WHERE, None, None, ".".join(path), exc.detail)]) from None
        raise SpecError([program.loaded.source.diagnostic(path, exc.detail)]) from None


@dataclass(frozen=True)
class EpisodeLength:
    """How many of the spec's steps one ``step()`` makes, and after how many an episode is truncated."""

    #: the spec's steps per step() (dm_control's action repeat), each with the same action
    action_repeat: int
    #: the spec's steps after which an episode is truncated: its max_steps, or Gymnasium's max_episode_steps step() calls
    step_limit: int
    #: episodes are truncated after this many step() calls
    max_episode_steps: int


def episode_length(program: Program, max_episode_steps: Any, action_repeat: Any) -> EpisodeLength:
    """The episode's length from the spec and the options (``None``: the spec's)."""
    repeat = program.spec.action_repeat if action_repeat is None else action_repeat
    if isinstance(repeat, bool) or not isinstance(repeat, (int, np.integer)) or repeat < 1:
        raise ValueError(f"action_repeat must be an integer of at least 1, got {action_repeat!r}")
    limit = program.spec.max_steps if max_episode_steps is None else step_limit(program, max_episode_steps) * repeat
    return EpisodeLength(int(repeat), limit, -(-limit // int(repeat)))


def camera_sensors(observation: Observation | None, space: spaces.Space) -> dict[str, SensorModel]:
    """The sensor of each observation key whose camera declares one (`space`: one env's observation space)."""
    views = views_plan(observation)
    if isinstance(space, spaces.Dict):
        return sensor_models(views, {key: sub.shape for key, sub in space.spaces.items()})  # type: ignore[misc]
    return sensor_models(views, {key: space.shape for key in views})  # type: ignore[misc]
