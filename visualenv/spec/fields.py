"""The spec's field types and the strict base model every part of the spec is made of.

An expression is kept as text (or a plain number) here and checked by :mod:`visualenv.expr` when the compiler
resolves names; a misspelt key or a quoted number is refused by :class:`StrictModel`.
"""

from typing import Annotated, Union

from pydantic import BaseModel, ConfigDict, Field


#: An expression: a number, a boolean or the text of an expression such as ``"x + tau * x_dot"``.
Expr = Annotated[Union[bool, int, float, str], Field(description="a number or an expression")]
#: A 3-vector: a list of three expressions, or one expression text such as ``"[x, 0, 0]"``.
Vec3Expr = Annotated[
    Union[Annotated[list[Expr], Field(min_length=3, max_length=3)], str],
    Field(description="three expressions, or one vector expression"),
]
#: A colour: three (RGB) or four (RGBA) expressions in 0..1, or one vector expression.
ColorExpr = Annotated[
    Union[Annotated[list[Expr], Field(min_length=3, max_length=4)], str],
    Field(description="RGB or RGBA in 0..1 (on a material, alpha below 1 is see-through)"),
]

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Color = Annotated[
    list[Annotated[float, Field(ge=0.0)]], Field(min_length=3, max_length=4, description="RGB or RGBA, linear, 0..1")
]
Name = Annotated[str, Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", description="an identifier")]
#: A name as Blender writes it (objects, cameras, scenes): dots, spaces and non-ASCII letters included, as in 'Cube.001'
BlenderName = Annotated[
    str,
    Field(
        pattern=r"^[^\x00-\x1f\x7f]+$",
        max_length=255,
        description="a Blender name, e.g. 'Cube.001' (any text without control characters)",
    ),
]
Resolution = Annotated[
    list[Annotated[int, Field(ge=4, le=8192)]],
    Field(min_length=2, max_length=2, description="[width, height] in pixels (Blender renders at least 4)"),
]


class StrictModel(BaseModel):
    """Unknown keys are errors and types are strict: a misspelt key or a quoted number must not be silently accepted.

    Strict mode refuses ``"10"`` for an integer, ``true`` for a number and ``"yes"``
    for a boolean (an integer is still accepted where a number is expected).
    """

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)
