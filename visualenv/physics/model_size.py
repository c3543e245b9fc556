"""What compiling an MJCF model will cost, estimated from its text and its files' headers before MuJoCo is asked to.

A few hundred bytes of MJCF can ask MuJoCo for gigabytes: a height field's ``nrow`` and ``ncol`` (or the image it
names), a builtin texture's ``width`` and ``height``, ``<size memory="8G"/>``. MuJoCo then allocates them, and the
machine swaps, or MuJoCo ends in an allocation error. :func:`check_model_size` reads the model and its includes
with expat (which builds no tree and expands no entities), the headers of the images and height field files they
name, and refuses a model whose estimate passes the limit or the machine's available memory, naming the element.
"""

from __future__ import annotations

import struct
import xml.parsers.expat
from dataclasses import dataclass
from pathlib import Path

from visualenv.files import MAX_IMAGE_PIXELS, MAX_MODEL_MEMORY_MIB, FileSizeError, check_image, image_size

#: MuJoCo's peak memory per height field cell while compiling (its elevation as floats in the spec, the model and
#: their copies: 16 bytes measured with MuJoCo 3.17), with room for the env's own copy of the model
HFIELD_CELL_BYTES = 20
#: per element (a body, geom, joint, site, ...) of the model, and per copy of it a ``<replicate count>`` makes, and per
#: point of a ``<flexcomp>`` or ``<composite count>``: MuJoCo 3.17 took 5.5 KB a geom compiling 90,000 replicated ones
ELEMENT_BYTES = 6 * 2**10
#: per texel of a texture: up to 4 channels of a byte, decoded once and copied into the model (8), and, when the
#: scene is drawn, the texture as float RGBA pixels for Blender and their copies (about 40 more)
TEXEL_BYTES = 48
#: the includes followed at most (a file including itself is followed once)
MAX_INCLUDES = 1000
_CUBE_FACES = ("fileright", "fileleft", "fileup", "filedown", "filefront", "fileback")
_UNITS = {"K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40, "P": 2**50, "E": 2**60}


@dataclass(frozen=True)
class _Element:
    file: Path
    line: int
    tag: str
    attrs: dict[str, str]
    copies: int = 1  # the product of the counts of the <replicate> elements around it

    def where(self) -> str:
        key = "name" if self.attrs.get("name") else "file"
        named = f" {key}='{self.attrs[key]}'" if key in self.attrs else ""
        copies = f" ({self.copies} copies)" if self.copies > 1 else ""
        return f"{self.file}:{self.line}: <{self.tag}{named}>{copies}"


def check_model_size(
    path: Path, max_mib: int = MAX_MODEL_MEMORY_MIB, max_pixels: int = MAX_IMAGE_PIXELS, available: int | None = None
) -> int:
    """The bytes compiling the MJCF at `path` is estimated to take; FileSizeError naming the file and element when an
    image passes `max_pixels`, or the estimate passes `max_mib` MiB or `available` bytes (default: the machine's
    available memory). A file the model names that is missing or unreadable is left to MuJoCo to report."""
    elements = _elements(path)
    costs = [(element, cost) for element in elements for cost in [_cost(element, elements, path, max_pixels)] if cost]
    total = sum(cost for _, cost in costs)
    if available is None:
        import psutil

        available = int(psutil.virtual_memory().available)
    limit, over = max_mib * 2**20, ""
    if total > limit:
        over = f"more than the limit of {max_mib} MiB (a spec's physics.max_memory_mib raises it for a model you trust)"
    elif total > available:
        over = f"more than this machine's available memory ({_gib(available)})"
    if over:
        largest = [c for c in sorted(costs, key=lambda c: -c[1])[:3] if c[1] * 20 >= total]  # 5% of it or more
        parts = "; ".join(f"{element.where()}: {_gib(cost)}" for element, cost in largest)
        raise FileSizeError(f"{path}: compiling this model would take about {_gib(total)}, {over}: {parts}")
    return total


def _gib(count: int) -> str:
    return f"{count / 2**30:.1f} GiB" if count >= 2**30 else f"{count / 2**20:.0f} MiB"


def _elements(path: Path) -> list[_Element]:
    """Every element of the model and of the files its ``<include>`` names, in order (expat: no tree, no recursion)."""
    out: list[_Element] = []
    seen: set[Path] = set()
    pending = [path]
    while pending and len(seen) < MAX_INCLUDES:
        file = pending.pop(0)
        if file in seen:
            continue
        seen.add(file)
        found = _parse(file)
        out.extend(found)
        for element in found:
            if element.tag == "include" and element.attrs.get("file"):
                name = Path(element.attrs["file"])
                beside = file.parent / name  # MuJoCo looks beside the model; an include beside its includer too
                pending.append(beside if beside.exists() else path.parent / name)
    return out


def _parse(file: Path) -> list[_Element]:
    """The elements of one XML file, with their lines; none for a file that cannot be read (MuJoCo says which)."""
    try:
        data = file.read_bytes()
    except OSError:
        return []
    found: list[_Element] = []
    copies = [1]  # of each open element's children
    parser = xml.parsers.expat.ParserCreate()

    def start(tag: str, attrs: dict[str, str]) -> None:
        found.append(_Element(file, parser.CurrentLineNumber, tag, attrs, copies[-1]))
        copies.append(copies[-1] * (_count(attrs.get("count", "1")) if tag == "replicate" else 1))

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: copies.pop()
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError:
        pass  # MuJoCo reports the XML error, with its line; what came before it is counted
    return found


def _asset_dir(elements: list[_Element], model: Path, kind: str) -> Path:
    """Where the model's files of `kind` ('texturedir', 'meshdir': also height fields) are, as <compiler> says."""
    folder = ""
    for element in elements:
        if element.tag == "compiler":
            folder = element.attrs.get(kind) or element.attrs.get("assetdir") or folder
    return model.parent / folder


def _count(text: str) -> int:
    """The product of a count attribute's numbers (``3``, or ``10 10 10`` for a grid); 1 for what is not a count."""
    product = 1
    for word in text.split():
        if not word.isdigit():
            return 1
        product *= int(word)
    return product


def _cost(element: _Element, elements: list[_Element], model: Path, max_pixels: int) -> int:
    return element.copies * (_own_cost(element, elements, model, max_pixels) + ELEMENT_BYTES)


def _own_cost(element: _Element, elements: list[_Element], model: Path, max_pixels: int) -> int:
    attrs = element.attrs
    if element.tag in ("flexcomp", "composite"):
        return _count(attrs.get("count", "1")) * ELEMENT_BYTES
    try:
        if element.tag == "size":
            return _memory(attrs.get("memory", "-1")) + max(0, int(attrs.get("nstack", "0"))) * 8
        if element.tag == "hfield":
            if attrs.get("file"):
                cells = _file_pixels(_asset_dir(elements, model, "meshdir") / attrs["file"], element, max_pixels)
            else:
                cells = max(0, int(attrs.get("nrow", "0"))) * max(0, int(attrs.get("ncol", "0")))
            return cells * HFIELD_CELL_BYTES
        if element.tag == "texture":
            return _texels(element, _asset_dir(elements, model, "texturedir"), max_pixels) * TEXEL_BYTES
    except FileSizeError:
        raise
    except ValueError:
        pass  # a number MuJoCo will refuse itself (and say where)
    return 0


def _memory(text: str) -> int:
    """MuJoCo's ``<size memory>``: bytes, or a number with K, M, G, T, P or E after it; -1 (the default): none."""
    text = text.strip()
    unit = _UNITS.get(text[-1:].upper(), 1)
    number = int(text[:-1] if unit > 1 else text)
    return max(0, number) * unit


def _texels(element: _Element, folder: Path, max_pixels: int) -> int:
    attrs = element.attrs
    if attrs.get("builtin", "none") != "none":
        width, height = int(attrs.get("width", "0")), int(attrs.get("height", "0"))
        pixels = 6 * width * width if attrs.get("type", "cube") in ("cube", "skybox") else width * height
        _check_pixels(pixels, element, max_pixels)
        return pixels
    files = [attrs[key] for key in ("file", *_CUBE_FACES) if attrs.get(key)]
    pixels = sum(_file_pixels(folder / name, element, max_pixels) for name in files)
    _check_pixels(pixels, element, max_pixels)
    return pixels


def _file_pixels(file: Path, element: _Element, max_pixels: int) -> int:
    """The pixels (or height field cells) of a file an element names: an image's header, else MuJoCo's binary
    format's (two int32, rows and columns, then the data: 4 bytes a cell, 3 a texel), if the file holds that data
    (else MuJoCo refuses the file, and says so)."""
    if not file.is_file():
        return 0
    try:
        size = image_size(file)
        if size is not None:
            check_image(file, max_pixels, "a spec's scene.max_image_pixels")
            return size[0] * size[1]
        with file.open("rb") as handle:
            head = handle.read(8)
        length = file.stat().st_size
    except FileSizeError as exc:
        raise FileSizeError(f"{element.where()}: {exc}") from None
    except OSError:
        return 0
    if len(head) < 8:
        return 0
    rows, columns = struct.unpack("<ii", head)
    pixels = max(0, rows) * max(0, columns)
    if length < 8 + pixels * (4 if element.tag == "hfield" else 3):
        return 0
    _check_pixels(pixels, element, max_pixels)
    return pixels


def _check_pixels(pixels: int, element: _Element, max_pixels: int) -> None:
    if pixels > max_pixels:
        raise FileSizeError(
            f"{element.where()}: {pixels} pixels, more than the {max_pixels} an image may have "
            "(a spec's scene.max_image_pixels raises the limit)"
        )
