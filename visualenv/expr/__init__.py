"""The expression language: an allow-listed subset of Python expressions.

:func:`check` parses and checks one expression against the names in scope;
:mod:`visualenv.expr.codegen` turns checked trees into fast Python functions.
See ``docs/spec.md`` for the language reference.
"""

from visualenv.expr.checker import Checked, check, parse
from visualenv.expr.functions import CONSTANTS, FUNCTIONS, RandomSource
from visualenv.expr.types import BOOL, NUM, Type, vec

__all__ = ["BOOL", "CONSTANTS", "FUNCTIONS", "NUM", "Checked", "RandomSource", "Type", "check", "parse", "vec"]
