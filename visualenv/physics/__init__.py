"""MuJoCo physics for specs: load an MJCF model, name its quantities, step it.

A layer beside :mod:`visualenv.expr`: the compiler asks it which names a model
has (so an unknown name is a located spec error) and the env steps one
:class:`~visualenv.physics.simulation.Simulation` per env. It never imports bpy:
a renderer reads body poses from the arrays it hands out.
"""

from visualenv.physics.model import INSTALL_HINT, PhysicsModel, load_model, mujoco_module, resolve_model_path

__all__ = ["INSTALL_HINT", "PhysicsModel", "load_model", "mujoco_module", "resolve_model_path"]
