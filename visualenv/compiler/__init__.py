"""Spec -> resolved program (generated init/step/bind functions and the renderer's plan)."""

from visualenv.compiler.program import BindingTarget, Program, compile_spec

__all__ = ["BindingTarget", "Program", "compile_spec"]
