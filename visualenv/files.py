"""Files and folders: the folders the commands write to (made before any work, so a bad path fails first), and the
files an installed package ships (found on disk, never imported)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

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
