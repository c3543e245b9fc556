"""Read YAML or TOML into plain data plus a map from field paths to positions.

Pydantic validates plain data, so positions must be kept aside: a
:class:`~visualenv.source_map.SourceMap` maps each path (a tuple of keys and list indexes) to the
line and column where its value starts, and to where the key itself is
written. Syntax errors become :class:`~visualenv.errors.SpecError` with the
parser's own position, explained (:mod:`visualenv.spec.yaml_pitfalls`). Duplicate keys, which YAML
parsers silently overwrite, are reported, and so are YAML 1.1's boolean words (``yes``, ``off``);
numbers with an exponent (``4e2``) are read as numbers, as YAML 1.2 reads them.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any, NoReturn

import yaml

from visualenv.errors import Diagnostic, SpecError
from visualenv.source_map import Position, SourceMap, SpecPath, format_path
from visualenv.spec.text_places import toml_places, yaml_places
from visualenv.spec.yaml_pitfalls import (
    EXPONENT_NUMBER,
    YAML11_BOOLEANS,
    boolean_word,
    explain_syntax_error,
    opens_and_closes,
)


#: the largest spec file read (1 MiB; the bundled specs are under 6 KB): a spec of megabytes takes minutes to parse
#: and check. Raise it in Python, ``visualenv.spec.source.MAX_SPEC_BYTES = ...``, for a generated spec you trust
MAX_SPEC_BYTES = 2**20


def load_document(path: str | Path) -> tuple[Any, SourceMap]:
    """Load a spec file (by extension: .yaml/.yml or .toml) with its source map; one over MAX_SPEC_BYTES is refused
    before it is read."""
    p = Path(path)
    name = str(path)
    try:
        with p.open("rb") as file:
            raw = file.read(MAX_SPEC_BYTES + 1)
        if len(raw) > MAX_SPEC_BYTES:
            raise SpecError([Diagnostic(name, None, None, "", too_large(p.stat().st_size))])
    except FileNotFoundError:
        raise SpecError([Diagnostic(name, None, None, "", "file not found")]) from None
    except OSError as exc:
        raise SpecError([Diagnostic(name, None, None, "", f"cannot read the file: {exc}")]) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        before = raw[: exc.start]
        line, column = before.count(b"\n") + 1, exc.start - (before.rfind(b"\n") + 1) + 1
        raise SpecError(
            [
                Diagnostic(
                    name, line, column, "", f"the file is not UTF-8 text: {exc.reason} (byte 0x{raw[exc.start]:02x})"
                )
            ]
        ) from None
    suffix = p.suffix.lower()
    if suffix == ".toml":
        return load_toml_text(text, name)
    if suffix in (".yaml", ".yml", ".json"):
        return load_yaml_text(text, name)
    raise SpecError(
        [Diagnostic(name, None, None, "", f"unknown spec file type '{suffix}': expected .yaml, .yml or .toml")]
    )


def too_large(size: int) -> str:
    """Why a spec of `size` bytes (characters, for text given in Python) is refused."""
    return (
        f"the spec is {size} bytes, more than the {MAX_SPEC_BYTES} a spec may have (a spec of megabytes takes "
        "minutes to check; docs/security.md#sizes-checked-before-reading says how to raise the limit)"
    )


# -- YAML -------------------------------------------------------------------------------------


#: YAML 1.1 base-60 numbers (``1:30`` is 90): read as text, so a typed field refuses them
BASE60 = re.compile(r"^[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+(?:\.[0-9_]*)?$")


class _PositionLoader(yaml.SafeLoader):
    """SafeLoader (no Python tags, no code) that keeps node positions."""

    def resolve(self, kind: type, value: Any, implicit: Any) -> str:
        if kind is yaml.ScalarNode and implicit[0] and BASE60.match(value):
            return "tag:yaml.org,2002:str"
        if kind is yaml.ScalarNode and implicit[0] and EXPONENT_NUMBER.match(value):
            return "tag:yaml.org,2002:float"  # YAML 1.2: 4e2 is 400.0 (YAML 1.1 reads it as text)
        return super().resolve(kind, value, implicit)


#: deepest nesting of mappings and lists a spec may have (PyYAML's composer recurses)
MAX_NESTING = 64
#: most values a document may hold once YAML aliases are expanded ("billion laughs")
MAX_VALUES = 100_000


#: the tags of plain YAML data: anything else (!!python/..., custom tags) is rejected
_PLAIN_TAGS = {f"tag:yaml.org,2002:{t}" for t in ("str", "int", "float", "bool", "null", "map", "seq", "timestamp")}


class _TooLarge(Exception):
    """More than MAX_VALUES values: raised at the node where the count ran over."""

    def __init__(self, node: yaml.Node):
        self.node = node


def _error_at(name: str, mark: Any, message: str) -> SpecError:
    """A spec error at a YAML mark (0-based line and column) of file `name`."""
    return SpecError([Diagnostic(name, mark.line + 1, mark.column + 1, "", message)])


def _check_structure(text: str, name: str) -> bool:
    """Reject too-deep nesting and recursive aliases before composing (the event parser does not recurse).

    Returns whether the document uses aliases, so a too-large document can be blamed on the right thing.
    """
    depth = 0
    aliases = False
    open_anchors: list[str | None] = []
    for event in yaml.parse(text, Loader=_PositionLoader):
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_NESTING:
                raise _error_at(
                    name, event.start_mark, f"nested too deeply (more than {MAX_NESTING} levels of mappings and lists)"
                )
            open_anchors.append(event.anchor)
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1
            open_anchors.pop()
        elif isinstance(event, yaml.AliasEvent):
            aliases = True
            if event.anchor in open_anchors:
                message = f"recursive YAML alias: '*{event.anchor}' is used inside its own anchor"
                raise _error_at(name, event.start_mark, message)
    return aliases


def load_yaml_text(text: str, name: str = "<string>") -> tuple[Any, SourceMap]:
    smap = SourceMap(name)
    try:
        aliases = _check_structure(text, name)
        node = yaml.compose(text, Loader=_PositionLoader)
    except yaml.reader.ReaderError as exc:  # a character YAML does not allow, such as a NUL byte
        before = text[: exc.position]
        line, column = before.count("\n") + 1, exc.position - (before.rfind("\n") + 1) + 1
        char = f"U+{exc.character:04X}" if isinstance(exc.character, int) else repr(exc.character)
        raise SpecError(
            [Diagnostic(name, line, column, "", f"YAML does not allow the control character {char} in a file")]
        ) from None
    except yaml.MarkedYAMLError as exc:
        at_line, at_column, message = explain_syntax_error(exc, text)
        raise SpecError([Diagnostic(name, at_line, at_column, "", message)]) from None
    except yaml.YAMLError as exc:
        raise SpecError([Diagnostic(name, None, None, "", f"YAML error: {exc}")]) from None
    except RecursionError:  # pragma: no cover - _check_structure limits the nesting first
        raise SpecError([Diagnostic(name, None, None, "", "nested too deeply")]) from None
    if node is None:
        raise SpecError([Diagnostic(name, 1, 1, "", "the file is empty: expected a mapping with at least 'id'")])
    problems: list[Diagnostic] = []
    try:
        data = _convert(node, (), smap, problems, [0])
    except _TooLarge as exc:
        why = " (YAML aliases expand to copies of what they name)" if aliases else ""
        raise SpecError(
            [Diagnostic(name, *_lc(exc.node), "", f"the document is too large: more than {MAX_VALUES} values{why}")]
        ) from None
    if problems:
        raise SpecError(problems)
    return data, smap


def _pos(node: yaml.Node) -> Position:
    text_offset = None
    if isinstance(node, yaml.ScalarNode) and node.start_mark.line == node.end_mark.line:
        text_offset = 1 if node.style in ("'", '"') else 0
    return Position(node.start_mark.line + 1, node.start_mark.column + 1, text_offset)


def _convert(node: yaml.Node, path: SpecPath, smap: SourceMap, problems: list[Diagnostic], count: list[int]) -> Any:
    count[0] += 1
    if count[0] > MAX_VALUES:
        raise _TooLarge(node)
    smap.values[path] = _pos(node)
    if node.tag not in _PLAIN_TAGS:  # e.g. !!python/object/apply: never constructed, reported
        problems.append(
            Diagnostic(
                smap.file,
                *_lc(node),
                format_path(path),
                f"YAML tags such as '{node.tag.replace('tag:yaml.org,2002:', '!!')}' are not allowed",
            )
        )
        return None
    if isinstance(node, yaml.CollectionNode) and node.flow_style and _split(node):
        smap.split[path] = "{" if isinstance(node, yaml.MappingNode) else "["
    if isinstance(node, yaml.MappingNode):
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                problems.append(
                    Diagnostic(smap.file, *_lc(key_node), format_path(path), "mapping keys must be plain names")
                )
                continue
            key = _scalar(key_node)
            if (isinstance(key, bool) or key is None) and key_node.style is None:
                problems.append(
                    Diagnostic(
                        smap.file,
                        *_lc(key_node),
                        format_path(path),
                        f"YAML 1.1 reads the key '{key_node.value}' as {_yaml_word(key)}: quote it ('{key_node.value}':)",
                    )
                )
                continue
            if key == "<<":
                problems.append(
                    Diagnostic(smap.file, *_lc(key_node), format_path(path), "YAML merge keys ('<<') are not supported")
                )
                continue
            if isinstance(key, float) and EXPONENT_NUMBER.match(key_node.value):
                key = key_node.value  # a key is a name: kept as written
            if not isinstance(key, (str, int, float, bool)):
                key = str(key)
            key = str(key) if not isinstance(key, str) else key
            child = path + (key,)
            if key in out:
                first = smap.keys[child]
                problems.append(
                    Diagnostic(
                        smap.file,
                        *_lc(key_node),
                        format_path(child),
                        f"duplicate key '{key}' (first defined on line {first.line})",
                    )
                )
                continue
            smap.keys[child] = _pos(key_node)
            out[key] = _convert(value_node, child, smap, problems, count)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_convert(item, path + (i,), smap, problems, count) for i, item in enumerate(node.value)]
    return _convert_scalar(node, path, smap, problems)


def _convert_scalar(node: yaml.ScalarNode, path: SpecPath, smap: SourceMap, problems: list[Diagnostic]) -> Any:
    if node.style is None and node.value.lower() in YAML11_BOOLEANS and node.tag == "tag:yaml.org,2002:bool":
        problems.append(Diagnostic(smap.file, *_lc(node), format_path(path), boolean_word(node.value)))
        return None
    try:
        value = _scalar(node)
    except ValueError as exc:  # e.g. an integer with more digits than Python converts
        problems.append(Diagnostic(smap.file, *_lc(node), format_path(path), f"cannot read this value: {_short(exc)}"))
        return None
    if isinstance(value, str) and smap.values[path].text_offset is None:  # a multi-line string: where each character is
        smap.values[path].places = yaml_places(node, value)
    return value


def _split(node: yaml.CollectionNode) -> bool:
    """Whether a flow collection's plain keys and values hold both halves of an expression cut at a comma
    (one leaves a bracket open, one closes a bracket it did not open; a bracket merely left out is not a comma's doing)."""
    items = [n for pair in node.value for n in pair] if isinstance(node, yaml.MappingNode) else list(node.value)
    halves = [opens_and_closes(n.value) for n in items if isinstance(n, yaml.ScalarNode) and n.style is None]
    return any(opens for opens, _ in halves) and any(closes for _, closes in halves)


def _yaml_word(value: Any) -> str:
    return "nothing (null)" if value is None else f"the boolean {str(value).lower()}"


def _short(exc: BaseException) -> str:
    text = str(exc)
    return "the number has too many digits" if "digits" in text and "limit" in text else text


def _lc(node: yaml.Node) -> tuple[int, int]:
    return node.start_mark.line + 1, node.start_mark.column + 1


def _scalar(node: yaml.ScalarNode) -> Any:
    return _PositionLoader.construct_scalar_value(node)


def _construct_scalar_value(node: yaml.ScalarNode) -> Any:
    loader = _PositionLoader("")
    try:
        return loader.construct_object(node, deep=True)
    except yaml.constructor.ConstructorError:
        return node.value


_PositionLoader.construct_scalar_value = staticmethod(_construct_scalar_value)


# -- the top-level values alone ------------------------------------------------------------------


def read_top_level(path: str | Path, keys: tuple[str, ...]) -> dict[str, Any]:
    """The top-level scalar values of `keys` in a spec file, read without positions or validation (registration's
    ids and ``max_steps``: every known spec is read when visualenv is imported).

    The same parsers and scalar rules as :func:`load_document` (YAML resolved and constructed as there; TOML by
    tomllib), with YAML's events read by libyaml where PyYAML has it, up to the keys sought. What precedes a syntax
    error is kept; a file that cannot be read gives {}. Errors are :func:`load_document`'s to report, with positions.
    """
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return {}
    if Path(path).suffix.lower() == ".toml":
        return _toml_top_level(text.removeprefix("\ufeff"), keys)
    return _yaml_top_level(text, keys)


#: YAML's event parser: libyaml's where PyYAML was built with it (several times faster than the pure-Python one)
_EVENT_LOADER: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def _yaml_top_level(text: str, keys: tuple[str, ...]) -> dict[str, Any]:
    found: dict[str, Any] = {}
    depth, is_key, key = 0, True, None
    try:
        for event in yaml.parse(text, Loader=_EVENT_LOADER):
            if isinstance(event, yaml.CollectionEndEvent):
                depth -= 1
            elif isinstance(event, yaml.DocumentEndEvent):
                break
            elif isinstance(event, yaml.NodeEvent):
                if depth == 0 and not isinstance(event, yaml.MappingStartEvent):
                    break  # not a mapping
                if depth == 1:
                    if is_key:
                        key = event.value if isinstance(event, yaml.ScalarEvent) else None
                    elif isinstance(event, yaml.ScalarEvent) and key in keys and key not in found:
                        found[key] = _event_value(event)
                        if len(found) == len(keys):
                            break
                    is_key = not is_key
                depth += isinstance(event, yaml.CollectionStartEvent)
    except yaml.YAMLError:
        pass
    return found


def _event_value(event: yaml.ScalarEvent) -> Any:
    """A scalar event's value as :func:`load_document` reads it (None for a tag it refuses)."""
    loader = _PositionLoader("")
    tag = event.tag if event.tag not in (None, "!") else loader.resolve(yaml.ScalarNode, event.value, event.implicit)
    if tag not in _PLAIN_TAGS:
        return None
    return _scalar(yaml.ScalarNode(tag, event.value, style=event.style))


def _toml_top_level(text: str, keys: tuple[str, ...]) -> dict[str, Any]:
    try:
        data = tomllib.loads(text)
    # what precedes the error's line, which holds the top-level keys if it is below them
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"\(at line (\d+)", str(exc))
        try:
            data = tomllib.loads("\n".join(text.splitlines()[: int(m.group(1)) - 1])) if m else {}
        except tomllib.TOMLDecodeError:
            data = {}
    except (ValueError, RecursionError):
        data = {}
    return {key: data[key] for key in keys if key in data and not isinstance(data[key], (dict, list))}


# -- TOML -------------------------------------------------------------------------------------

_TABLE = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(
    r"""(?:^|[{,])\s*((?:[A-Za-z0-9_-]+|"[^"]*"|'[^']*')(?:\s*\.\s*(?:[A-Za-z0-9_-]+|"[^"]*"|'[^']*'))*)\s*=\s*"""
)


def load_toml_text(text: str, name: str = "<string>") -> tuple[Any, SourceMap]:
    """Parse TOML with tomllib and recover key positions by scanning the text.

    tomllib keeps no positions, so keys are located line by line: table headers
    set the current prefix and each `key =` (also inside inline tables) is
    recorded. It is exact for the usual layouts and falls back to the enclosing
    table otherwise.
    """
    text = text.removeprefix("\ufeff")  # a byte order mark: tomllib does not skip it
    try:
        data = tomllib.loads(text)
    except RecursionError:
        raise SpecError(
            [
                Diagnostic(
                    name,
                    *_deepest(text),
                    "",
                    f"nested too deeply (more than {MAX_NESTING} levels of tables and arrays)",
                )
            ]
        ) from None
    except ValueError as exc:
        if isinstance(exc, tomllib.TOMLDecodeError):
            _toml_syntax_error(exc, text, name)
        m = re.search(r"\d{1000,}", text)
        at_line, at_col = (
            (text.count("\n", 0, m.start()) + 1, m.start() - text.rfind("\n", 0, m.start())) if m else (None, None)
        )
        raise SpecError([Diagnostic(name, at_line, at_col, "", f"cannot read this value: {_short(exc)}")]) from None
    if not data:
        raise SpecError([Diagnostic(name, 1, 1, "", "the file is empty: expected a table with at least 'id'")])
    smap = SourceMap(name)
    smap.values[()] = Position(1, 1)
    prefix: SpecPath = ()
    array_counts: dict[SpecPath, int] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.split("#", 1)[0] if '"' not in line and "'" not in line else line
        m = _TABLE.match(stripped)
        if m and "=" not in stripped.split("]")[0]:
            keys = tuple(_split_key(m.group(2)))
            if m.group(1) == "[[":
                index = array_counts.get(keys, 0)
                array_counts[keys] = index + 1
                prefix = keys + (index,)
            else:
                prefix = keys
            smap.values.setdefault(prefix, Position(lineno, line.index("[") + 1))
            smap.keys.setdefault(prefix, Position(lineno, line.index("[") + 1))
            continue
        # keys in `a = 1` and inside inline tables `{ b = 2, c = 3 }` (one level deep)
        inline_prefix = prefix
        for km in _KEY.finditer(line):
            keys = tuple(_split_key(km.group(1)))
            before = line[: km.start(1)]
            full = (inline_prefix if "{" in before else prefix) + keys
            if "{" not in before:
                inline_prefix = full
            col = km.start(1) + 1
            value_col = km.end() + 1
            smap.keys.setdefault(full, Position(lineno, col))
            is_string = km.end() < len(line) and line[km.end()] in "\"'"
            single = is_string and not line[km.end() :].startswith(('"""', "'''"))
            smap.values.setdefault(full, Position(lineno, value_col, 1 if single else None))
    for path, pos in smap.values.items():  # multi-line strings: where each character is
        value = _toml_value(data, path) if pos.text_offset is None else None
        if isinstance(value, str):
            pos.places = toml_places(text, pos.line, pos.column, value)
    return data, smap


def _toml_value(data: Any, path: SpecPath) -> Any:
    for part in path:
        try:
            data = data[part]
        except (KeyError, IndexError, TypeError):
            return None
    return data


def _toml_syntax_error(exc: Exception, text: str, name: str) -> NoReturn:
    msg = str(exc)
    m = re.search(r"\(at line (\d+), column (\d+)\)", msg)
    line, col = (int(m.group(1)), int(m.group(2))) if m else (None, None)
    if m is None and "(at end of document)" in msg:
        lines = text.splitlines() or [""]
        line, col = len(lines), len(lines[-1]) + 1
    msg = re.sub(r"\s*\(at (line \d+, column \d+|end of document)\)", "", msg)
    raise SpecError([Diagnostic(name, line, col, "", f"TOML syntax error: {msg}")]) from None


def _deepest(text: str) -> tuple[int | None, int | None]:
    """Roughly where bracket nesting first goes past MAX_NESTING (strings are not skipped)."""
    depth = 0
    for lineno, line in enumerate(text.splitlines(), start=1):
        for col, char in enumerate(line, start=1):
            depth += char in "[{"
            depth -= char in "]}"
            if depth > MAX_NESTING:
                return lineno, col
    return None, None


def _split_key(key: str) -> list[str]:
    parts = re.findall(r"""[A-Za-z0-9_-]+|"[^"]*"|'[^']*'""", key)
    return [p[1:-1] if p[:1] in "\"'" else p for p in parts]
