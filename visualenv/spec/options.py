"""The options of :func:`visualenv.make`, checked with the spec's own models and messages.

An option given in Python overrides a field of the spec (``device``,
``threads``, ``samples``, ``engine``, ``noise`` override ``render``) or adds a wrapper
(``frame_stack``, ``grayscale``, ``resize``). Each is validated as strictly
as the same value written in a spec, so ``device="tpu"`` or ``samples=0``
fails at ``make()`` with the message the spec would give, located at
``visualenv.make()`` instead of a file line.
"""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath
from typing import Annotated, Any, Literal, Mapping, Optional, Sequence, Union

from pydantic import Field, ValidationError, field_validator

from visualenv.errors import SpecError
from visualenv.spec.loader import diagnostics_of
from visualenv.spec.models import Distractions, Name, RenderSettings, Spec, StrictModel, VideoBackground
from visualenv.spec.view_models import DifficultyRange
from visualenv.source_map import SourceMap

#: where option errors are reported (in place of file:line)
WHERE = "visualenv.make()"

_Pixels = Annotated[int, Field(ge=1, le=8192)]
#: the Distracting Control Suite's levels, by the names its paper gives them
DISTRACTION_LEVELS = {"easy": 0.1, "medium": 0.2, "hard": 0.3}
#: the suite's ground_plane_alpha by DeepMind Control domain (the model file's name), and every other domain's
DCS_FLOOR_ALPHA, DEFAULT_FLOOR_ALPHA = {"reacher": 0.0, "walker": 1.0, "cheetah": 1.0}, 0.3


class MakeOptions(StrictModel):
    """The options of make() that are not render fields: the env kind, params and the image wrappers."""

    render: Optional[bool] = Field(None, description="False: the state-only env (no Blender)")
    render_mode: Optional[Literal["rgb_array", "human"]] = None
    params: Optional[dict[Name, Union[bool, int, float, str]]] = Field(
        None, description="overrides of the spec's params"
    )
    frame_stack: Optional[Annotated[int, Field(ge=1, le=64)]] = Field(None, description="stack this many frames")
    grayscale: bool = False
    resize: Optional[tuple[_Pixels, _Pixels]] = Field(None, description="(width, height) of the observation")
    max_episode_steps: Optional[Annotated[int, Field(ge=1, le=100_000_000)]] = Field(
        None,
        description="Gymnasium's name: episodes are truncated after this many steps, in place of the spec's max_steps",
    )
    action_repeat: Optional[Annotated[int, Field(ge=1, le=10_000)]] = Field(
        None,
        description="the spec's steps per step() with the same action, rewards summed (in place of the spec's action_repeat)",
    )
    distractions: Optional[
        Union[Annotated[float, Field(ge=0.0, le=1.0)], DifficultyRange, Literal["easy", "medium", "hard"], Distractions]
    ] = Field(
        None,
        description="a difficulty (every kind, fixed per episode), a range [low, high] (each episode's drawn in it), one "
        "of the Distracting Control Suite's levels by name (easy 0.1, medium 0.2, hard 0.3) or the spec's distractions "
        "section as a dict; 0 turns the spec's off",
    )

    trust_code: bool = Field(
        False, description="import the module the spec's dynamics.python names (it runs code): the caller's consent"
    )

    @field_validator("distractions", mode="before")
    @classmethod
    def _a_level_by_name(cls, value: Any) -> Any:
        if isinstance(value, str) and value not in DISTRACTION_LEVELS:
            raise ValueError(
                f"expected a difficulty from 0 to 1, a level by name ({', '.join(DISTRACTION_LEVELS)}) or a mapping, got {value!r}"
            )
        return value


def distraction_settings(
    given: float | Sequence[float] | str | Mapping[str, Any] | Distractions | None,
    spec: Distractions | None,
    model: str | None = None,
    base_dir: Path | None = None,
) -> Distractions | None:
    """The distractions an env draws: the option's (a difficulty or a range, a level's name, or a section as a dict), else the spec's;
    None for none (a difficulty of 0, or no kind on and no floor alpha below 1). A floor alpha of ``"dcs"`` is the
    suite's for the domain of `model` (the physics model's file, :func:`floor_alpha`). A folder of background videos is
    made absolute: the spec's relative to `base_dir` (its folder), the option's to the working directory."""
    if isinstance(given, str):
        given = DISTRACTION_LEVELS[given]
    if given is None:
        chosen = spec
        if chosen is not None and base_dir is not None:
            chosen = with_videos_from(chosen, base_dir)
    elif isinstance(given, Distractions):
        chosen = given
    elif isinstance(given, Mapping):
        chosen = Distractions.model_validate(dict(given))
    elif isinstance(given, Sequence):
        chosen = Distractions(difficulty=[float(v) for v in given])
    else:
        chosen = Distractions(difficulty=float(given))
    if given is not None and chosen is not None:
        chosen = with_videos_from(chosen, Path.cwd())
    if chosen is not None and chosen.floor_alpha == "dcs":
        chosen = chosen.model_copy(update={"floor_alpha": floor_alpha(model)})
    faded = chosen is not None and isinstance(chosen.floor_alpha, float) and chosen.floor_alpha < 1
    if chosen is None or chosen.largest <= 0 or not (chosen.camera or chosen.colors or chosen.background or faded):
        return None
    return chosen


def with_videos_from(chosen: Distractions, base: Path) -> Distractions:
    """`chosen` with its background's folder of videos absolute (``~`` and ``$VARIABLES`` expanded, then under `base`)."""
    videos = chosen.background
    if not isinstance(videos, VideoBackground):
        return chosen
    folder = base / Path(os.path.expandvars(os.path.expanduser(videos.videos)))
    return chosen.model_copy(update={"background": videos.model_copy(update={"videos": str(folder)})})


def model_file(spec: Spec) -> str | None:
    """The spec's physics model file (None without physics)."""
    return spec.physics.model if spec.physics is not None else None


def floor_alpha(model: str | None) -> float:
    """The Distracting Control Suite's floor alpha for a physics model's file: by its name, the DeepMind Control domain
    (``reacher.xml``: 0), else :data:`DEFAULT_FLOOR_ALPHA`."""
    domain = PurePosixPath(model.replace("\\", "/")).stem if model else ""
    return DCS_FLOOR_ALPHA.get(domain, DEFAULT_FLOOR_ALPHA)


class _DistractionsSection(StrictModel):
    """``distractions`` given as a mapping: checked as the spec's section alone (not as either branch of the option)."""

    distractions: Distractions


def check_make_options(**options: Any) -> None:
    """Raise :class:`SpecError` for any of the given options a spec would refuse.

    The render overrides (any field of ``RenderSettings``) are validated by the spec's own ``RenderSettings``
    model (the env asks, for its ``RendererOptions``), the rest by :class:`MakeOptions` (``make`` asks).
    """
    if isinstance(options.get("resize"), list):  # [w, h] reads as well as (w, h)
        options["resize"] = tuple(options["resize"])
    problems = []
    render = tuple(RenderSettings.model_fields)
    checks: list[tuple[type[StrictModel], tuple[str, ...]]] = [
        (RenderSettings, render),
        (MakeOptions, tuple(MakeOptions.model_fields)),
    ]
    # checked as the spec's section alone, not as either branch of the option
    if isinstance(options.get("distractions"), Mapping):
        options["distractions"] = dict(options["distractions"])
        checks = [
            (RenderSettings, render),
            (MakeOptions, tuple(k for k in MakeOptions.model_fields if k != "distractions")),
            (_DistractionsSection, ("distractions",)),
        ]
    for model, names in checks:
        given = {k: options[k] for k in names if options.get(k) is not None}
        try:
            model.model_validate(given)
        except ValidationError as exc:
            problems.extend(diagnostics_of(exc, given, SourceMap(WHERE)))
    if problems:
        raise SpecError(problems)
