"""Spec -> resolved program -> Gymnasium env."""

from visualenv.compiler.env import VisualEnv
from visualenv.compiler.program import BindingTarget, Program, compile_spec

__all__ = ["BindingTarget", "Program", "VisualEnv", "compile_spec"]
