"""Rendering: the renderer interface, its plan and the Blender (bpy) backend."""

from visualenv.render.base import Renderer, create_renderer
from visualenv.render.plan import BindingTarget, RenderPlan

__all__ = ["BindingTarget", "RenderPlan", "Renderer", "create_renderer"]
