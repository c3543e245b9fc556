"""Find specs by path, build folder or id; register the bundled ones with Gymnasium."""

from __future__ import annotations

import json
import os
from pathlib import Path

import gymnasium as gym

from visualenv.errors import Diagnostic, SpecError, did_you_mean

NAMESPACE = "visualenv"
SPEC_SUFFIXES = (".yaml", ".yml", ".toml")
#: ``gymnasium.make("visualenv/<Id>", **options)`` builds what ``visualenv.make(spec, **options)`` builds,
#: wrappers included (as ALE's ids take their preprocessing options); named as text, so this module never imports it
ENTRY_POINT = "visualenv.env.make:make"
#: ``gymnasium.make_vec("visualenv/<Id>", N, vectorization_mode="vector_entry_point")``: N envs in one Blender (env/batched.py)
VECTOR_ENTRY_POINT = "visualenv.env.batched:make_batched"
#: where the bundled specs live: package data in a wheel; in a checkout, a link to the repository's specs/ folder
BUNDLED_DIR = (Path(__file__).parents[1] / "specs").resolve()


def spec_dirs() -> list[Path]:
    """Bundled specs, then folders listed in $VISUALENV_SPECS_PATH (os.pathsep separated)."""
    extra = [Path(p) for p in os.environ.get("VISUALENV_SPECS_PATH", "").split(os.pathsep) if p]
    return [BUNDLED_DIR, *extra]


def spec_index() -> dict[str, Path]:
    """Every known spec by its id (read from the files' `id:` line, without full validation)."""
    index: dict[str, Path] = {}
    for folder in spec_dirs():
        if not folder.is_dir():
            continue
        for path in sorted(folder.iterdir()):
            if path.suffix in SPEC_SUFFIXES:
                env_id = _read_id(path)
                if env_id:
                    index.setdefault(env_id, path)
    return index


def _read_id(path: Path) -> str | None:
    for line in path.read_text(encoding="utf-8").splitlines():
        stripped = line.strip()
        if stripped.startswith("id:") or stripped.startswith("id ="):
            value = stripped.split(":", 1)[1] if stripped.startswith("id:") else stripped.split("=", 1)[1]
            return value.split("#", 1)[0].strip().strip("\"'") or None
    return None


def resolve(target: str | os.PathLike[str]) -> Path:
    """A spec file for `target`: a spec path, a build folder (its env.json), or an id."""
    path = Path(target)
    if path.is_dir() and (path / "env.json").is_file():
        record_file = path / "env.json"
        try:
            source = Path(json.loads(record_file.read_text())["source"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise SpecError([Diagnostic(str(record_file), None, None, "", f"not a build record of `visualenv build` ({type(exc).__name__}: {exc}): build the spec again")]) from None
        if not source.is_file():
            raise SpecError([Diagnostic(str(record_file), None, None, "source", f"the spec it was built from is gone: {source}")])
        return source
    if path.suffix in SPEC_SUFFIXES or path.exists():
        return path
    name = str(target)
    if name.startswith(NAMESPACE + "/"):
        name = name[len(NAMESPACE) + 1:]
    index = spec_index()
    if name in index:
        return index[name]
    raise SpecError([Diagnostic(str(target), None, None, "", "not a spec file, build folder or known env id" + did_you_mean(name, index).replace("names:", "ids:"))])


def register_bundled() -> list[str]:
    """Register every bundled spec as `visualenv/<Id>` (idempotent)."""
    ids = []
    for env_id, path in spec_index().items():
        full = f"{NAMESPACE}/{env_id}"
        if full not in gym.registry:
            gym.register(id=full, entry_point=ENTRY_POINT, vector_entry_point=VECTOR_ENTRY_POINT, kwargs={"target": str(path)})
        ids.append(full)
    return ids
