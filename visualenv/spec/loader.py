"""Load a spec file and validate it against the models, keeping every error.

:func:`load_spec` returns a :class:`LoadedSpec` (the validated model, its
source map for later error messages, and the folder relative paths resolve
against) or raises :class:`~visualenv.errors.SpecError` listing every problem
as ``file:line:column: field.path: message``.
"""

from __future__ import annotations

import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError
from pydantic.fields import FieldInfo

from visualenv.errors import Diagnostic, SpecError, did_you_mean, in_file_order
from visualenv.source_map import COMMA_HINT
from visualenv.spec.models import Spec
from visualenv.spec import source as spec_source
from visualenv.spec.source import BASE60, SourceMap, format_path, load_document, load_toml_text, load_yaml_text
from visualenv.spec.unused import unused_fields
from visualenv.spec.yaml_pitfalls import split_at_comma

_OBJECT_KINDS = ("primitive", "mesh", "light", "camera", "empty")
#: what the patterns of the models mean, in words
_PATTERNS = {
    r"^[A-Za-z][A-Za-z0-9_.-]*-v\d+$": "an id such as 'MyEnv-v0' (a letter, then letters, digits, '_', '.' or '-', then '-v' and a version number)",
    r"^[A-Za-z_][A-Za-z0-9_]*$": "a name made of letters, digits and '_', not starting with a digit",
    r"^[^\x00-\x1f\x7f]+$": "a Blender name (any text without control characters, e.g. 'Cube.001')",
    r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$": "'module:function', e.g. 'mypackage.dynamics:step'",
}
#: names other tools (Blender's Python API first) give the fields of a spec, for "did you mean" where spelling is no guide
_SYNONYMS = {
    "energy": "strength",
    "power": "strength",
    "intensity": "strength",
    "colour": "color",
    "position": "location",
    "pos": "location",
    "focal_length": "lens",
    "target": "look_at",
    "hidden": "visible",
    "hide": "visible",
    "rotation_euler": "rotation",
    "steps": "max_steps",
}
_TYPE_NAMES = {
    bool: "a boolean",
    int: "an integer",
    float: "a number",
    str: "text",
    list: "a list",
    dict: "a mapping",
    type(None): "nothing",
}


@dataclass(frozen=True)
class LoadedSpec:
    """A validated spec with where it came from."""

    spec: Spec
    source: SourceMap
    base_dir: Path

    @property
    def file(self) -> str:
        return self.source.file


def load_spec(path: str | Path) -> LoadedSpec:
    """Read and validate a YAML or TOML spec file."""
    data, smap = load_document(path)
    return validate_data(data, smap, Path(path).resolve().parent)


def spec_identity(path: str | Path) -> dict[str, str]:
    """The spec file's id and the sha256 of its bytes: what a run or a policy file records of the spec it was made on."""
    import hashlib

    return {"id": load_spec(path).spec.id, "sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest()}


def load_spec_text(text: str, name: str = "<string>.yaml", base_dir: str | Path = ".") -> LoadedSpec:
    """Validate spec text (YAML, or TOML when `name` ends in .toml), of at most MAX_SPEC_BYTES characters."""
    if len(text) > spec_source.MAX_SPEC_BYTES:
        raise SpecError([Diagnostic(name, None, None, "", spec_source.too_large(len(text)))])
    data, smap = load_toml_text(text, name) if name.endswith(".toml") else load_yaml_text(text, name)
    return validate_data(data, smap, Path(base_dir).resolve())


def validate_data(data: Any, smap: SourceMap, base_dir: Path) -> LoadedSpec:
    if not isinstance(data, dict):
        raise SpecError(
            [smap.diagnostic((), f"expected a mapping of spec fields at the top level, got {_type_name(data)}")]
        )
    try:
        spec = Spec.model_validate(data)
    except ValidationError as exc:
        raise SpecError(_diagnostics(exc, data, smap)) from None
    unused = unused_fields(spec)
    if unused:
        raise SpecError([smap.diagnostic(path, message, key=True) for path, message in unused])
    return LoadedSpec(spec, smap, base_dir)


# -- turning pydantic errors into located, readable diagnostics ----------------------------------------


def diagnostics_of(exc: ValidationError, data: Any, smap: SourceMap) -> list[Diagnostic]:
    """Readable diagnostics for a model's validation error, located by `smap` (also used for API options)."""
    return _diagnostics(exc, data, smap)


def _diagnostics(exc: ValidationError, data: Any, smap: SourceMap) -> list[Diagnostic]:
    grouped: dict[tuple, list[Any]] = {}
    for err in exc.errors(include_url=False):
        path = _data_path(err["loc"], data, keep_last=err["type"] in ("missing", "extra_forbidden"))
        grouped.setdefault(path, []).append(err)
    out: list[Diagnostic] = []
    for path, errs in grouped.items():
        message = _message(path, errs, data) + _misplaced_hint(path, errs, data)
        out.append(smap.diagnostic(path, message, key=errs[0]["type"] == "extra_forbidden"))
    out[:] = in_file_order(out)
    return out


def _data_path(loc: tuple, data: Any, keep_last: bool) -> tuple:
    """Drop the union-branch labels pydantic adds to `loc`, keeping keys that exist in the data."""
    path: list[Any] = []
    node = data
    for i, part in enumerate(loc):
        last = i == len(loc) - 1
        nxt = loc[i + 1] if not last else None
        if isinstance(node, dict) and part in node:
            value = node[part]
            # a discriminator tag ('primitive') followed by a sibling key: the tag is a label
            if nxt is not None and part in _OBJECT_KINDS and nxt in node and not isinstance(value, (dict, list)):
                continue
            path.append(part)
            node = value
        elif isinstance(node, (list, tuple)) and isinstance(part, int) and 0 <= part < len(node):
            path.append(part)
            node = node[part]
        elif last and keep_last:
            path.append(part)
        # otherwise: a label such as 'int', 'list[...]' or a Tag: skip it
    return tuple(path)


def _message(path: tuple, errs: list[dict], data: Any) -> str:
    err = errs[0]
    kind = err["type"]
    if kind == "extra_forbidden":
        return _unknown_key_message(path, data)
    if kind == "missing":
        return f"missing required field '{path[-1]}'"
    value = _value_at(path, data)
    if len(errs) > 1 and all(e["type"].endswith("_type") or e["type"] in ("list_type", "string_type") for e in errs):
        # a union (number-or-expression, list-or-text...) rejected every branch
        wanted = {_expected(e) for e in errs}
        if {"a number", "text"} <= wanted:
            wanted = {"a number or an expression"} | ({"a list of expressions"} if "a list" in wanted else set())
        return f"expected {' or '.join(sorted(wanted))}, got {_type_name(value)}"
    for candidate in errs:  # a validator's own message is the most specific
        if candidate["type"] in ("value_error", "assertion_error", "object_kind"):
            err = candidate
            break
    msg = err["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, ") :]
    if err["type"] == "string_pattern_mismatch":
        pattern = err.get("ctx", {}).get("pattern", "")
        what = _PATTERNS.get(pattern, f"text matching {pattern}")
        return f"expected {what}, got {err.get('input')!r}"
    if err["type"] in ("too_short", "too_long"):
        return _length_message(err, path)
    if err["type"] == "literal_error":
        return _literal_message(err, value)
    if err["type"].endswith("_type") or err["type"] in (
        "int_from_float",
        "bool_parsing",
        "float_parsing",
        "int_parsing",
    ):
        if isinstance(value, (dict, list)):
            return f"expected {_expected(err)}, got {_type_name(value)}"
        return f"expected {_expected(err)}, got {_type_name(value)} {value!r}" + _strict_hint(_expected(err), value)
    if msg.startswith("Input should be "):
        msg = "expected a value " + msg[len("Input should be ") :] + f", got {value!r}"
    return msg


def _misplaced_hint(path: tuple, errs: list[dict], data: Any) -> str:
    """A key written at the wrong indentation: an unknown key that a parent takes, or a wrongly typed entry that each entry takes."""
    if not path or not isinstance(path[-1], str) or errs[0]["type"] == "missing":
        return ""
    key = path[-1]
    if errs[0]["type"] == "extra_forbidden":
        for depth in range(len(path) - 2, -1, -1):
            if key in _fields_at(path[:depth], data):
                where = f"'{format_path(path[:depth])}'" if depth else "the top level"
                return f" ('{key}' belongs to {where}: is it indented too far?)"
        return ""
    if (
        len(path) >= 2
        and not isinstance(_value_at(path, data), dict)
        and key in _fields_at(path, data)
        and not _fields_at(path[:-1], data)
    ):
        parent = format_path(path[:-1])
        return f" ('{key}' is a field of each entry of '{parent}': is it indented too little, beside the entries instead of inside one?)"
    return ""


def _length_message(err: dict, path: tuple) -> str:
    """A list or mapping of the wrong size, with both bounds when the field has them: "exactly 3 values", "3 or 4 values"."""
    ctx = err.get("ctx", {})
    bound = ctx.get("min_length") if err["type"] == "too_short" else ctx.get("max_length")
    side = 0 if err["type"] == "too_short" else 1
    bounds = [b for b in _length_bounds(path) if b[side] == bound and None not in b]
    low, high = bounds[0] if len(bounds) == 1 else (None, None)
    if low is not None and high is not None:
        count = f"exactly {low}" if low == high else (f"{low} or {high}" if high == low + 1 else f"{low} to {high}")
        bound = high
    else:
        count = f"{'at least' if side == 0 else 'at most'} {bound}"
    items = (
        ("entr" + ("y" if bound == 1 else "ies"))
        if ctx.get("field_type") == "Dictionary"
        else ("value" + ("" if bound == 1 else "s"))
    )
    return f"expected {count} {items}, got {ctx.get('actual_length')}"


def _length_bounds(path: tuple) -> set[tuple[int | None, int | None]]:
    """(min_length, max_length) of each list type the models allow at `path` (every union branch is followed)."""
    current: list[tuple[Any, tuple]] = [(Spec, ())]
    for part in path:
        following: list[tuple[Any, tuple]] = []
        for annotation, meta in current:
            for base, _ in _branches(annotation, meta):
                origin, args = typing.get_origin(base), typing.get_args(base)
                if isinstance(base, type) and issubclass(base, BaseModel):
                    field = base.model_fields.get(str(part))
                    if field is not None:
                        following.append((field.annotation, tuple(field.metadata)))
                elif origin is dict and isinstance(part, str) and len(args) == 2:
                    following.append((args[1], ()))
                elif origin is list and isinstance(part, int) and args:
                    following.append((args[0], ()))
        current = following
    bounds = set()
    for annotation, meta in current:
        for base, constraints in _branches(annotation, meta):
            if typing.get_origin(base) in (list, dict):
                low = next((c.min_length for c in constraints if getattr(c, "min_length", None) is not None), None)
                high = next((c.max_length for c in constraints if getattr(c, "max_length", None) is not None), None)
                bounds.add((low, high))
    return bounds


def _branches(annotation: Any, meta: tuple = ()) -> list[tuple[Any, tuple]]:
    """Each alternative type of `annotation` (through Annotated, Optional and unions) with the constraints written on it."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        base, *extra = typing.get_args(annotation)
        more: list[Any] = []
        for item in extra:
            more += item.metadata if isinstance(item, FieldInfo) else [item]
        return _branches(base, (*meta, *more))
    if origin in (typing.Union, types.UnionType):
        return [b for arg in typing.get_args(annotation) for b in _branches(arg, meta)]
    return [(annotation, meta)]


def _unknown_key_message(path: tuple, data: Any) -> str:
    """An unknown key, with the keys allowed there; a key that is half an expression means YAML split it at a comma."""
    key = str(path[-1])
    if split_at_comma(key):
        return f"unknown key '{key}': {COMMA_HINT['{']}"
    allowed = _fields_at(path[:-1], data)
    synonym = _SYNONYMS.get(key.lower())
    if synonym in allowed:
        return f"unknown key '{key}' (did you mean '{synonym}'? expected one of: {', '.join(allowed)})"
    return f"unknown key '{path[-1]}'" + (
        did_you_mean(str(path[-1]), allowed).replace("names:", "expected one of:") if allowed else ""
    )


def _literal_message(err: dict, value: Any) -> str:
    """A value outside a fixed set of words, with the closest word when there is one."""
    expected = err.get("ctx", {}).get("expected", "")
    options = [o.strip(" '") for o in expected.replace(" or ", ",").split(",") if o.strip()]
    msg = f"expected one of {expected}, got {value!r}"
    if isinstance(value, str):
        hint = did_you_mean(value, options)
        if "did you mean" in hint:
            msg += " (" + hint.split("?")[0].strip(" (") + "?)"
    return msg


def _strict_hint(expected: str, value: Any) -> str:
    """Why a value that looks right is refused (types are strict: no quoted numbers, no 1 for true)."""
    if isinstance(value, str) and BASE60.match(value.strip()):
        return " (YAML 1.1 would read it as a base-60 number; write the number itself)"
    if isinstance(value, str) and expected in ("an integer", "a number"):
        try:
            float(value)
        except ValueError:
            return ""
        return " (write the number without quotes)"
    if isinstance(value, float) and expected == "an integer" and value.is_integer() and abs(value) < 1e16:
        return f" (an integer is written with digits only, without a decimal point or exponent: {int(value)})"
    if (
        isinstance(value, str)
        and expected == "a boolean"
        and value.strip().lower() in ("true", "false", "yes", "no", "on", "off")
    ):
        return " (write true or false without quotes)"
    if isinstance(value, bool) and expected in ("an integer", "a number"):
        return " (a boolean is not a number)"
    return ""


def _expected(err: dict) -> str:
    kind = err["type"]
    return {
        "bool_type": "a boolean",
        "bool_parsing": "a boolean",
        "int_type": "an integer",
        "int_parsing": "an integer",
        "int_from_float": "an integer",
        "float_type": "a number",
        "float_parsing": "a number",
        "string_type": "text",
        "list_type": "a list",
        "tuple_type": "a tuple",
        "dict_type": "a mapping",
        "model_type": "a mapping",
        "model_attributes_type": "a mapping",
    }.get(kind, kind.replace("_", " "))


def _type_name(value: Any) -> str:
    return _TYPE_NAMES.get(type(value), type(value).__name__)


def _value_at(path: tuple, data: Any) -> Any:
    node = data
    for part in path:
        try:
            node = node[part]
        except (KeyError, IndexError, TypeError):
            return None
    return node


def _fields_at(path: tuple, data: Any) -> list[str]:
    """Names of the fields the model at `path` accepts (for 'did you mean')."""
    annotation: Any = Spec
    node = data
    for part in path:
        annotation = _unwrap(annotation, node)
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            field = annotation.model_fields.get(str(part))
            if field is None:
                return []
            annotation = field.annotation
        else:
            origin = typing.get_origin(annotation)
            args = typing.get_args(annotation)
            if origin is dict and len(args) == 2:
                annotation = args[1]
            elif origin is list and args:
                annotation = args[0]
            else:
                return []
        node = (
            node.get(part)
            if isinstance(node, dict)
            else (node[part] if isinstance(node, list) and isinstance(part, int) and part < len(node) else None)
        )
    annotation = _unwrap(annotation, node)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return list(annotation.model_fields)
    return []


def _unwrap(annotation: Any, node: Any) -> Any:
    """Strip Annotated/Optional/unions down to the model class that matches `node`."""
    for _ in range(10):
        origin = typing.get_origin(annotation)
        if origin is typing.Annotated:
            annotation = typing.get_args(annotation)[0]
            continue
        if origin in (typing.Union, types.UnionType):
            models = [
                a
                for a in (_strip(x) for x in typing.get_args(annotation))
                if isinstance(a, type) and issubclass(a, BaseModel)
            ]
            containers = [a for a in typing.get_args(annotation) if typing.get_origin(_strip(a)) in (dict, list)]
            if isinstance(node, dict) and len(models) > 1:
                for model in models:
                    kind = next((k for k in _OBJECT_KINDS if k in model.model_fields and k in node), None)
                    if kind:
                        return model
                return models[0]
            if models:
                return models[0]
            if containers:
                annotation = _strip(containers[0])
                continue
            return annotation
        return annotation
    return annotation


def _strip(annotation: Any) -> Any:
    while typing.get_origin(annotation) is typing.Annotated:
        annotation = typing.get_args(annotation)[0]
    return annotation


__all__ = ["LoadedSpec", "load_spec", "load_spec_text", "spec_identity", "validate_data", "format_path"]
