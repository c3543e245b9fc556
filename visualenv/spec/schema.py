"""JSON Schema of the spec format, generated from the pydantic models."""

from __future__ import annotations

from typing import Any

from visualenv.spec.models import Spec


def spec_json_schema() -> dict[str, Any]:
    """The schema editors use to validate and complete spec files (YAML and TOML)."""
    schema = Spec.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "visualenv spec"
    return schema
