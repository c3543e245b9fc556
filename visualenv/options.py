"""The options of :func:`visualenv.make`, checked with the spec's own models and messages.

An option given in Python overrides a field of the spec (``device``,
``threads``, ``samples``, ``engine`` override ``render``) or adds a wrapper
(``frame_stack``, ``grayscale``, ``resize``). Each is validated as strictly
as the same value written in a spec, so ``device="tpu"`` or ``samples=0``
fails at ``make()`` with the message the spec would give, located at
``visualenv.make()`` instead of a file line.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Optional, Union

from pydantic import Field, ValidationError, create_model

from visualenv.errors import SpecError
from visualenv.spec.loader import diagnostics_of
from visualenv.spec.models import Name, Render, StrictModel
from visualenv.spec.source import SourceMap

#: where option errors are reported (in place of file:line)
WHERE = "visualenv.make()"
#: the render fields an option of the same name overrides
RENDER_OVERRIDES = ("engine", "samples", "device", "threads")

_Pixels = Annotated[int, Field(ge=1, le=8192)]


def _render_field(name: str) -> tuple[Any, Any]:
    field = Render.model_fields[name]
    annotation = Annotated[(field.annotation, *field.metadata)] if field.metadata else field.annotation
    return Optional[annotation], Field(None, description=field.description)


MakeOptions = create_model(
    "MakeOptions",
    __base__=StrictModel,
    __doc__="The keyword options of visualenv.make(), gymnasium.make('visualenv/...') and make_vec.",
    render=(Optional[bool], Field(None, description="False: the state-only env (no Blender)")),
    render_mode=(Optional[Literal["rgb_array"]], None),
    params=(Optional[dict[Name, Union[bool, int, float, str]]], Field(None, description="overrides of the spec's params")),
    frame_stack=(Optional[Annotated[int, Field(ge=1, le=64)]], Field(None, description="stack this many frames")),
    grayscale=(bool, False),
    resize=(Optional[tuple[_Pixels, _Pixels]],
            Field(None, description="(width, height) of the observation")),
    **{name: _render_field(name) for name in RENDER_OVERRIDES},
)


def check_make_options(**options: Any) -> None:
    """Raise :class:`SpecError` for any option a spec would refuse (unknown renderer options are left to the renderer)."""
    known = {k: v for k, v in options.items() if k in MakeOptions.model_fields and v is not None}
    if isinstance(known.get("resize"), list):  # [w, h] reads as well as (w, h)
        known["resize"] = tuple(known["resize"])
    try:
        MakeOptions.model_validate(known)
    except ValidationError as exc:
        raise SpecError(diagnostics_of(exc, known, SourceMap(WHERE))) from None
