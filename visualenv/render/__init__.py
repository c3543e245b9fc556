"""Rendering: the renderer interface and the Blender (bpy) backend."""

from visualenv.render.base import BindingTarget, RenderPlan, Renderer, create_renderer, observation_space

__all__ = ["BindingTarget", "RenderPlan", "Renderer", "create_renderer", "observation_space"]
