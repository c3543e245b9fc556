"""Find specs by path, build folder or id; register specs with Gymnasium as ``visualenv/<Id>``.

Ids come from three places, in this order: the bundled specs, every spec file
in the folders of ``$VISUALENV_SPECS_PATH`` (read when visualenv is imported),
and the files or folders given to :func:`register`. Two files with the same id
are an error naming both, never one of them silently winning.
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path

import gymnasium as gym

from visualenv.errors import Diagnostic, SpecError, did_you_mean
from visualenv.spec.loader import load_spec
from visualenv.spec.models import Spec
from visualenv.spec.source import Position, load_document, read_top_level

NAMESPACE = "visualenv"
SPEC_SUFFIXES = (".yaml", ".yml", ".toml")
#: ``gymnasium.make("visualenv/<Id>", **options)`` builds what ``visualenv.make(spec, **options)`` builds,
#: wrappers included (as ALE's ids take their preprocessing options); named as text, so this module never imports it
ENTRY_POINT = "visualenv.env.make:make"
#: ``gymnasium.make_vec("visualenv/<Id>", N, vectorization_mode="vector_entry_point")``: N envs in one Blender (env/batch.py)
VECTOR_ENTRY_POINT = "visualenv.env.batch:make_batched"
#: where the bundled specs live: package data in a wheel; in a checkout, a link to the repository's specs/ folder
BUNDLED_DIR = (Path(__file__).parents[1] / "specs").resolve()
#: the environment variable naming folders of the user's own specs (os.pathsep separated)
SPECS_PATH_VARIABLE = "VISUALENV_SPECS_PATH"
#: ids given to register() in this process, with their files
_REGISTERED: dict[str, Path] = {}
#: ids given to register(..., trust_code=True): their ``dynamics.python`` is imported by gymnasium.make
_TRUSTED: set[str] = set()


def spec_dirs() -> list[Path]:
    """Bundled specs, then folders listed in $VISUALENV_SPECS_PATH (os.pathsep separated)."""
    extra = [Path(p) for p in os.environ.get(SPECS_PATH_VARIABLE, "").split(os.pathsep) if p]
    # mujoco/: physics specs (Gymnasium's MuJoCo envs), apart until batches step them; dmc/: DeepMind Control's tasks
    return [BUNDLED_DIR, BUNDLED_DIR / "mujoco", BUNDLED_DIR / "dmc", *extra]


def spec_files(folder: Path) -> list[Path]:
    """The spec files directly in `folder` (.yaml, .yml, .toml), by name."""
    return sorted(p for p in folder.iterdir() if p.suffix in SPEC_SUFFIXES and p.is_file())


def spec_index() -> dict[str, Path]:
    """Every known spec by its id (read from the files' top-level `id` line, without full validation); the first file of an id."""
    return _scan()[0]


def _scan() -> tuple[dict[str, Path], dict[str, list[Path]]]:
    """(the first file of each id, the files of each id defined more than once)."""
    index: dict[str, Path] = {}
    clashes: dict[str, list[Path]] = {}
    files = [path for folder in spec_dirs() if folder.is_dir() for path in spec_files(folder)]
    for path in [*files, *_REGISTERED.values()]:
        env_id = read_header(path)[0]
        if not env_id:
            continue
        first = index.setdefault(env_id, path)
        if _same(first, path):
            continue
        known = clashes.setdefault(env_id, [first])
        if not any(_same(p, path) for p in known):
            known.append(path)
    return index, clashes


def _same(a: Path, b: Path) -> bool:
    return a.resolve() == b.resolve()


def read_header(path: Path) -> tuple[str | None, int | None]:
    """The top-level ``id`` and ``max_steps`` of a spec file, without validating it (every spec is read on import):
    read by the spec layer's own parsers (:func:`visualenv.spec.source.read_top_level`); None for either when absent or
    not an id or a step count, which loading the spec then reports. Kept per file version: ids are looked up often."""
    return _header_values(path)[:2]


def read_action_repeat(path: Path) -> int:
    """The top-level ``action_repeat`` of a spec file (1 where absent or not a count, which loading then reports)."""
    return _header_values(path)[2]


def _header_values(path: Path) -> tuple[str | None, int | None, int]:
    try:
        stat = path.stat()
    except OSError:
        return None, None, 1
    return _header(str(path), stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=4096)
def _header(path: str, mtime_ns: int, size: int) -> tuple[str | None, int | None, int]:
    values = read_top_level(path, ("id", "max_steps", "action_repeat"))
    env_id, max_steps, repeat = values.get("id"), values.get("max_steps"), values.get("action_repeat")
    return (
        env_id if isinstance(env_id, str) and env_id else None,
        max_steps if _count(max_steps) else None,
        repeat if _count(repeat) else 1,
    )  # type: ignore[return-value]


def _count(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


def time_limit(max_steps: int | None, action_repeat: int) -> int | None:
    """The id's ``max_episode_steps`` (Gymnasium's TimeLimit): the spec's max_steps, or none for a spec that repeats actions.

    A spec with ``action_repeat`` truncates its episodes itself after max_steps of its own steps,
    whatever repeat ``make`` is given; a TimeLimit counted in ``step()`` calls could only be right for one.
    """
    return max_steps if action_repeat == 1 else None


def _duplicate_id(env_id: str, files: list[Path]) -> SpecError:
    """Two or more files defining one id: named, each at its `id` (as the loader locates it)."""
    first, *others = files
    problems = []
    for path in others:
        where = _id_position(path)
        problems.append(
            Diagnostic(
                str(path),
                where.line if where else None,
                where.column if where else None,
                "id",
                f"the id '{env_id}' is also defined by {first}: give one of the two specs another id (e.g. a new -vN)",
            )
        )
    return SpecError(problems)


def _id_position(path: Path) -> Position | None:
    """Where the file's `id` key is written (None if the file does not load): an error's location, so read in full."""
    try:
        return load_document(path)[1].keys.get(("id",))
    except SpecError:
        return None


def resolve(target: str | os.PathLike[str]) -> Path:
    """A spec file for `target`: a spec path, a build folder (its env.json), or an id."""
    path = Path(target)
    if path.is_dir() and (path / "env.json").is_file():
        record_file = path / "env.json"
        try:
            source = Path(json.loads(record_file.read_text())["source"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise SpecError(
                [
                    Diagnostic(
                        str(record_file),
                        None,
                        None,
                        "",
                        f"not a build record of `visualenv build` ({type(exc).__name__}: {exc}): build the spec again",
                    )
                ]
            ) from None
        if not source.is_file():
            raise SpecError(
                [Diagnostic(str(record_file), None, None, "source", f"the spec it was built from is gone: {source}")]
            )
        return source
    if path.suffix in SPEC_SUFFIXES or path.exists():
        return path
    name = str(target)
    if name.startswith(NAMESPACE + "/"):
        name = name[len(NAMESPACE) + 1 :]
    index, clashes = _scan()
    if name in clashes:
        raise _duplicate_id(name, clashes[name])
    if name in index:
        return index[name]
    raise SpecError(
        [
            Diagnostic(
                str(target),
                None,
                None,
                "",
                "not a spec file, build folder or known env id"
                + did_you_mean(name, index).replace("names:", "ids:")
                + f"; your own specs: visualenv.register(path) or the folders in ${SPECS_PATH_VARIABLE}",
            )
        ]
    )


def _register_id(env_id: str, target: str, max_steps: int | None) -> str:
    """``visualenv/<env_id>`` in Gymnasium's registry (replaced quietly when it names the same thing)."""
    full = f"{NAMESPACE}/{env_id}"
    kwargs: dict[str, object] = {"target": target}
    if env_id in _TRUSTED:
        kwargs["trust_code"] = True
    old = gym.registry.get(full)
    if old is not None and old.kwargs == kwargs and old.max_episode_steps == max_steps:
        return full
    gym.registry.pop(full, None)
    gym.register(
        id=full,
        entry_point=ENTRY_POINT,
        vector_entry_point=VECTOR_ENTRY_POINT,
        kwargs=kwargs,
        max_episode_steps=max_steps,
    )
    return full


def register_bundled() -> list[str]:
    """Register every bundled spec and every spec in $VISUALENV_SPECS_PATH as `visualenv/<Id>` (idempotent).

    An id defined by two files is registered by its id alone, so that making it raises the error naming both.
    """
    index, clashes = _scan()
    default_steps = Spec.model_fields["max_steps"].default
    ids = []
    for env_id, path in index.items():
        if env_id in clashes:
            ids.append(_register_id(env_id, env_id, None))
            continue
        max_steps = read_header(path)[1]
        ids.append(
            _register_id(
                env_id,
                str(path),
                time_limit(max_steps if max_steps is not None else default_steps, read_action_repeat(path)),
            )
        )
    return ids


def register(target: str | os.PathLike[str], *, trust_code: bool = False) -> list[str]:
    """Register a spec file, or every spec file in a folder, as ``visualenv/<Id>``; returns the registered ids.

    >>> visualenv.register("my_specs/")           # doctest: +SKIP
    ['visualenv/Docking2D-v0']
    >>> env = gymnasium.make("visualenv/Docking2D-v0")   # doctest: +SKIP

    Each spec is validated first (a :class:`SpecError` lists its problems, every file's at once), and
    its ``max_steps`` becomes the id's ``max_episode_steps``. An id is then known to ``visualenv.make``
    and the CLI as well. Registering a file again is harmless; a second file with an id that is
    already known (bundled, in $VISUALENV_SPECS_PATH, or registered before) is a SpecError naming both files.

    Registering reads the specs as data. A spec whose ``dynamics.python`` names a module is made by
    ``gymnasium.make`` only if registered with ``trust_code=True`` (or made with ``trust_code=True``): importing the
    module runs its code (docs/security.md).
    """
    path = Path(target)
    if path.is_dir():
        files = spec_files(path)
        if not files:
            raise SpecError(
                [Diagnostic(str(path), None, None, "", f"no spec files ({', '.join(SPEC_SUFFIXES)}) in this folder")]
            )
    else:
        files = [path]
    problems: list[Diagnostic] = []
    specs: dict[str, tuple[Path, int | None]] = {}
    for file in files:
        try:
            spec = load_spec(file).spec
        except SpecError as exc:
            problems += exc.diagnostics
            continue
        if spec.id in specs:
            problems += _duplicate_id(spec.id, [specs[spec.id][0], file]).diagnostics
            continue
        specs[spec.id] = (file, time_limit(spec.max_steps, spec.action_repeat))
    index = {**spec_index(), **_REGISTERED}
    for env_id, (file, _) in specs.items():
        known = _REGISTERED.get(env_id) or index.get(env_id)
        if known is not None and not _same(known, file):
            problems += _duplicate_id(env_id, [known, file]).diagnostics
    if problems:
        raise SpecError(problems)
    ids = []
    for env_id, (file, max_steps) in specs.items():
        _REGISTERED[env_id] = file.resolve()
        if trust_code:
            _TRUSTED.add(env_id)
        else:
            _TRUSTED.discard(env_id)
        ids.append(_register_id(env_id, str(file.resolve()), max_steps))
    return ids
