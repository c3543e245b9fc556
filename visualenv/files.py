"""Files and folders: the folders the commands write to (made before any work, so a bad path fails first), the
files an installed package ships (found on disk, never imported), and the sizes of files from elsewhere read from
their headers before they are (JSON, images, ``.npy`` arrays: docs/security.md#sizes-checked-before-reading)."""

from __future__ import annotations

import importlib.util
import json
import re
import struct
import sys
import warnings
from pathlib import Path
from typing import Any, BinaryIO

from visualenv.errors import VisualEnvError

#: the prefix of a path inside an installed Python package: ``package:<package.sub>/<path inside it>``
PACKAGE_PREFIX = "package:"


def make_dir(path: Path) -> Path:
    """``mkdir -p`` that reports a folder it cannot make as a user error, before any work is done."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise VisualEnvError(f"cannot create the folder {path}: {exc.strerror or exc}") from None
    return path


def package_file(text: str) -> Path:
    """The file ``package:<package.sub>/<path inside it>`` names, found without importing (or running) any package.

    A spec is data: ``importlib.util.find_spec('a.b')`` imports ``a`` (running its ``__init__``), so only
    the top-level package is looked up (finding a top-level name asks the import finders where it would
    load from and runs none of its code; namespace packages have several folders) and its subpackages
    are its folders on disk. The file itself may not exist: the caller says so, naming the path.
    """
    rest = text[len(PACKAGE_PREFIX) :] if text.startswith(PACKAGE_PREFIX) else text
    package, _, inner = rest.partition("/")
    parts = package.split(".")
    if not inner or not all(part.isidentifier() for part in parts):
        raise VisualEnvError(
            f"'{text}': expected package:<package>/<path inside it>, e.g. package:mypackage.models/arm.xml"
        )
    folders = [folder.joinpath(*parts[1:]) for folder in _package_folders(parts[0])]
    folders = [folder for folder in folders if folder.is_dir()]
    if not folders:
        raise VisualEnvError(f"'{text}': no installed package '{package}'")
    return next((folder / inner for folder in folders if (folder / inner).exists()), folders[0] / inner)


def _package_folders(top: str) -> list[Path]:
    """Where the top-level package `top` is installed (several folders for a namespace package); none for a module or no package."""
    module = sys.modules.get(top)
    if module is not None:  # imported already (by the user or a dependency): its folders, without importing anything
        return [Path(p) for p in getattr(module, "__path__", None) or []]
    try:
        found = importlib.util.find_spec(top)  # a top-level name: no parent package to import
    except (ImportError, ValueError):
        return []
    return [Path(p) for p in (found.submodule_search_locations or [])] if found is not None else []


# -- sizes read before a file is: a small file from elsewhere must not make visualenv allocate gigabytes ---------------

#: the most pixels an image a spec names may have (textures, skies, heightmaps, an MJCF's textures and height fields):
#: 8192 x 8192; a spec raises it with ``scene.max_image_pixels``
MAX_IMAGE_PIXELS = 8192 * 8192
#: the most memory compiling an MJCF model may take, estimated from its text and files (height fields, textures,
#: ``<size memory>``) before MuJoCo is asked to; a spec raises it with ``physics.max_memory_mib``
MAX_MODEL_MEMORY_MIB = 1024
#: the largest JSON file read from a run folder or beside a policy (config.json, results.json, policy.json)
MAX_JSON_BYTES = 16 * 2**20
#: the deepest nesting of lists and objects in such a file: visualenv's own nest a few levels
MAX_JSON_DEPTH = 64


class FileSizeError(VisualEnvError, ValueError):
    """A file whose header, or size, asks for more than visualenv's limit (the message says which, and how to raise it).

    A ValueError too, so a reader that reports a malformed file as "not JSON (...)" reports this one with it.
    """


def read_json(path: Path, max_bytes: int | None = None, max_depth: int | None = None) -> Any:
    """JSON from a file that may come from elsewhere: its size and nesting checked before it is parsed.

    ``json.loads`` recurses once per level: 200,000 nested brackets end in a RecursionError. The depth is counted
    first, over the text with its strings taken out (brackets inside strings do not nest). OSError and
    UnicodeDecodeError as reading gives them; a file too large, too deep or not JSON is a ValueError, whose message
    does not name the file (the caller's error does). The limits default to MAX_JSON_BYTES and MAX_JSON_DEPTH, read
    when called (so setting them raises the limits everywhere).
    """
    max_bytes = MAX_JSON_BYTES if max_bytes is None else max_bytes
    max_depth = MAX_JSON_DEPTH if max_depth is None else max_depth
    with path.open("rb") as file:
        raw = file.read(max_bytes + 1)
    if len(raw) > max_bytes:
        raise FileSizeError(f"larger than the {max_bytes} bytes visualenv reads from a JSON file")
    text = raw.decode("utf-8")
    depth = json_depth(raw)
    if depth > max_depth:
        raise FileSizeError(f"lists and objects nested {depth} deep, more than the {max_depth} levels visualenv reads")
    try:
        return json.loads(text)
    except RecursionError:  # only if max_depth was raised beyond what the interpreter's stack holds
        raise FileSizeError("lists and objects nested too deeply to be read") from None


def read_json_as(path: Path, error: type[Exception], max_bytes: int | None = None) -> Any:
    """:func:`read_json`, its failures raised as `error` with the file's name: it cannot be read (OSError), or it is
    not JSON (too large, too deep, not UTF-8, not JSON: the ValueErrors)."""
    try:
        return read_json(path, max_bytes=max_bytes)
    except OSError as exc:
        raise error(f"{path}: cannot read it ({exc.strerror or exc})") from None
    except ValueError as exc:
        raise error(f"{path}: not JSON ({exc})") from None


def check_format(record: Any, path: Path, what: str, format: str, version: int, error: type[Exception]) -> dict:
    """`record` (JSON read from `path`) if it is `what` of visualenv (``"format": format``) in `version`, else `error`."""
    if not isinstance(record, dict) or record.get("format") != format:
        raise error(f'{path}: not {what} of visualenv (no "format": "{format}")')
    if record.get("format_version") != version:
        raise error(f"{path}: format_version {record.get('format_version')!r}; this visualenv reads version {version}")
    return record


#: a JSON string, escapes included
_JSON_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)


def json_depth(text: str | bytes) -> int:
    """The deepest nesting of lists and objects in JSON text, counted without parsing it (in C loops: fast on
    megabytes, a megabyte at a time)."""
    import numpy as np

    raw = text.encode("utf-8") if isinstance(text, str) else text
    bare = np.frombuffer(_JSON_STRING.sub(b'""', raw), dtype=np.uint8)
    depth = deepest = 0
    for start in range(0, bare.size, 2**20):
        chunk = bare[start : start + 2**20]
        steps = ((chunk == ord("[")) | (chunk == ord("{"))).astype(np.int32) - (
            (chunk == ord("]")) | (chunk == ord("}"))
        )
        running = np.cumsum(steps, dtype=np.int64) + depth
        deepest, depth = max(deepest, int(running.max())), int(running[-1])
    return deepest


def image_size(path: Path) -> tuple[int, int] | None:
    """(width, height) of an image file, read from its header without decoding it; None for what is not an image.

    PNG, JPEG, OpenEXR and Radiance HDR headers are read here; any other format Pillow identifies (TIFF, BMP,
    WebP, TGA, ...) by Pillow, which reads only the header on opening. An image beyond Pillow's own bomb limit
    (twice ``PIL.Image.MAX_IMAGE_PIXELS``) is a FileSizeError, as Pillow stops there without saying its size.
    OSError as reading the file gives it.
    """
    with path.open("rb") as file:
        head = file.read(32)
        file.seek(0)
        for reader in (_png_size, _jpeg_size, _exr_size, _hdr_size):
            size = reader(head, file)
            if size is not None:
                return size
    return _pillow_size(path)


def check_image(path: Path, max_pixels: int, raise_with: str) -> tuple[int, int]:
    """(width, height) of the image at `path`, if it is an image of at most `max_pixels` pixels; FileSizeError otherwise.

    `raise_with` says how the user raises the limit (e.g. "scene.max_image_pixels"). An image whose header is not
    read (a format neither this module nor Pillow knows, or not an image) is refused too: its size is unknown.
    """
    size = image_size(path)
    if size is None:
        raise FileSizeError(
            f"cannot read {path}: not an image whose size can be read from its header (PNG, JPEG, OpenEXR, Radiance HDR, or "
            "a format Pillow reads, such as TIFF, BMP, WebP, TGA)"
        )
    width, height = size
    if width * height > max_pixels:
        raise FileSizeError(
            f"{path} is {width} x {height} pixels, more than the {max_pixels} an image may have "
            f"(checked before it is read; {raise_with} raises the limit)"
        )
    return size


def _png_size(head: bytes, file: BinaryIO) -> tuple[int, int] | None:
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return struct.unpack(">II", head[16:24])


def _jpeg_size(head: bytes, file: BinaryIO) -> tuple[int, int] | None:
    """The frame header (SOF) of a JPEG, found by skipping the segments before it (EXIF, ICC profiles, tables)."""
    if head[:2] != b"\xff\xd8":
        return None
    file.seek(2)
    while True:
        marker = file.read(2)
        while marker[:1] == b"\xff" and marker[1:2] == b"\xff":  # fill bytes before a marker
            marker = marker[1:] + file.read(1)
        if len(marker) < 2 or marker[0] != 0xFF:
            return None
        length = file.read(2)
        if len(length) < 2 or struct.unpack(">H", length)[0] < 2:
            return None
        if 0xC0 <= marker[1] <= 0xCF and marker[1] not in (0xC4, 0xC8, 0xCC):
            frame = file.read(5)
            if len(frame) < 5:
                return None
            height, width = struct.unpack(">HH", frame[1:5])
            return width, height
        file.seek(struct.unpack(">H", length)[0] - 2, 1)


def _exr_size(head: bytes, file: BinaryIO) -> tuple[int, int] | None:
    """The data window of an OpenEXR file's (first part's) header: attributes named, typed and sized up to an empty name."""
    if head[:4] != b"\x76\x2f\x31\x01":
        return None
    header = file.read(1 << 20)[8:]  # magic and version; no header of a real image comes near a megabyte
    at = 0
    while at < len(header) and header[at] != 0:
        name_end = header.find(b"\0", at)
        type_end = header.find(b"\0", name_end + 1)
        if name_end < 0 or type_end < 0 or len(header) < type_end + 5:
            return None
        (size,) = struct.unpack("<i", header[type_end + 1 : type_end + 5])
        if size < 0:
            return None
        value = header[type_end + 5 : type_end + 5 + size]
        if header[at:name_end] == b"dataWindow" and len(value) == 16:
            x0, y0, x1, y1 = struct.unpack("<4i", value)
            return max(0, x1 - x0 + 1), max(0, y1 - y0 + 1)
        at = type_end + 5 + size
    return None


def _hdr_size(head: bytes, file: BinaryIO) -> tuple[int, int] | None:
    """A Radiance HDR file's resolution line (``-Y rows +X columns``), after its header's empty line."""
    if not (head.startswith(b"#?RADIANCE") or head.startswith(b"#?RGBE")):
        return None
    lines = file.read(64 * 1024).split(b"\n")
    if b"" not in lines[:-1]:
        return None
    words = lines[lines.index(b"") + 1].split()
    if len(words) != 4 or not (words[1].isdigit() and words[3].isdigit()):
        return None
    first, second = int(words[1]), int(words[3])  # "-Y rows +X columns" as usual; "+X columns -Y rows" transposed
    return (second, first) if words[0][1:] == b"Y" else (first, second)


def _pillow_size(path: Path) -> tuple[int, int] | None:
    from PIL import Image, UnidentifiedImageError

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            with Image.open(path) as image:
                return image.size
        except Image.DecompressionBombError:
            raise FileSizeError(
                f"{path} has more than {2 * (Image.MAX_IMAGE_PIXELS or 0)} pixels, beyond what Pillow opens"
            ) from None
        except (UnidentifiedImageError, ValueError, SyntaxError, struct.error):
            return None


def npy_header(path: Path, max_values: int | None = None) -> tuple[tuple[int, ...], Any]:
    """(shape, dtype) of a ``.npy`` file, read from its header; FileSizeError for more than `max_values` values,
    ValueError for a file that is not one or is shorter than its header says (a small file whose header claims a huge
    array is refused before anything is allocated)."""
    import numpy as np
    from numpy.lib import format as npy

    with path.open("rb") as file:
        version = npy.read_magic(file)
        if version == (1, 0):
            shape, _, dtype = npy.read_array_header_1_0(file)
        elif version == (2, 0):
            shape, _, dtype = npy.read_array_header_2_0(file)
        else:
            raise ValueError(f"a .npy file of format version {version[0]}.{version[1]}: 1.0 and 2.0 are read")
        if dtype.hasobject:
            raise ValueError(f"an array of Python objects ({dtype}): only numbers are read")
        count = int(np.prod(shape, dtype=object))
        if max_values is not None and count > max_values:
            raise FileSizeError(f"its header says {' x '.join(map(str, shape))}: more than {max_values} values")
        need = count * dtype.itemsize
        have = path.stat().st_size - file.tell()
    if have < need:
        raise ValueError(
            f"its header says {'x'.join(map(str, shape))} of {dtype} ({need} bytes), the file holds {have}"
        )
    return tuple(shape), dtype
