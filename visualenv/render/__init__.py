"""Rendering: the renderer interface and the Blender (bpy) backend."""

from visualenv.render.base import RenderPlan, Renderer, create_renderer, observation_space

__all__ = ["RenderPlan", "Renderer", "create_renderer", "observation_space"]
