"""The spec file format: pydantic models, YAML/TOML loading with positions, JSON Schema."""

from visualenv.spec.loader import LoadedSpec, load_spec, load_spec_text
from visualenv.spec.models import Spec

__all__ = ["LoadedSpec", "Spec", "load_spec", "load_spec_text"]
