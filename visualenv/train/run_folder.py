"""The run folder: the files a training run writes, the format of its config.json, and the migration of older runs.

Every module that writes or reads a run goes through here; none other spells a file name of a run.
A run folder ``runs/<Id>/<timestamp>/`` (:func:`new_run_dir`) holds:

* ``config.json``      the command, the settings and the versions (:func:`write_config`, :func:`read_config`)
* ``results.json``     the final evaluation on fresh seeds and the periodic one that picked the model
* ``evaluations.npz``  the periodic evaluations, in the arrays of SB3's EvalCallback (which names the file)
* ``logs/``            ``progress.csv`` (``progress-1.csv``, ... for the segments before each ``--resume``),
                       TensorBoard events; RLlib runs add ``env_steps_by_node.json``
* ``monitor/``         per-episode returns and lengths of SB3's training envs
* ``best_model.safetensors``, ``final_model.safetensors`` (each with its ``.json``): the best and the last policy
                       as policy files, which ``eval`` and ``play`` load without unpickling
* SB3: ``best_model.zip``, ``final_model.zip`` (pickles), ``checkpoints/latest/`` (data, for ``--resume``: see
  :mod:`visualenv.train.checkpoints`); RLlib: ``best_model/``, ``final_model/``, ``checkpoints/latest/`` (pickles)
* ``plots/``           the paper's figures; distillation: ``rounds.csv``, one row per DAgger round

A shipped agent's folder (``results/<Id>/``) keeps ``config.json``, ``results.json``, ``evaluations.npz``, the
plots and the logs beside them (no ``logs/``), and the best policy as ``policy.safetensors``.

config.json (format :data:`FORMAT_VERSION`) holds ``format`` and ``format_version``, ``backend`` (``sb3``, ``rllib``
or ``distill``), ``command``, ``config`` (the settings: :class:`~visualenv.train.sb3.TrainConfig`,
:class:`~visualenv.train.rllib.RLlibTrainConfig` or :class:`~visualenv.train.distill.DistillConfig` as a mapping),
``versions``, ``spec_path``, ``spec`` (id, sha256); ``resumes`` (each resume's command and changes); a distillation's
``teacher`` and ``student`` (path and sha256). Reading checks the type and the bounds of every setting.
"""

from __future__ import annotations

import csv
import itertools
import json
import shlex
import sys
import time
import zipfile
from dataclasses import asdict, dataclass, field, is_dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from visualenv.files import read_json_as
from visualenv.train.policy_format import WEIGHTS
from visualenv.train.run_settings import (
    ADDED,
    FORMAT,
    FORMAT_VERSION,
    MAX_RESETS_BEFORE,
    RunFolderError,
    check_record,
    check_results,
    finite_number,
)

LEGACY_EVAL_OFFSET = 10_000  # runs before the seed bands picked and reported on one stream: the run's seed + this

MAX_EVALUATIONS_BYTES = 2**28  # evaluations.npz's arrays, their size read from its zip directory before decompressing
LOGS, PROGRESS = "logs", "progress.csv"
SHIPPED_POLICY = "policy" + WEIGHTS
CHECKPOINT_STEPS = "visualenv.json"  # in each RLlib checkpoint folder: the env steps it had trained, and the time
STATE_WEIGHTS, STATE_JSON, STATE_REPLAY = "weights.safetensors", "state.json", "replay_buffer.npz"  # SB3's checkpoint


class RunFolder:
    """The paths of the files a run folder holds (see the module's docstring), named once."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"RunFolder({str(self.path)!r})"

    @property
    def config(self) -> Path:
        """The command, the settings and the versions."""
        return self.path / "config.json"

    @property
    def results(self) -> Path:
        """The final evaluation."""
        return self.path / "results.json"

    @property
    def evaluations(self) -> Path:
        """The periodic evaluations (SB3's EvalCallback names it, given log_path=path)."""
        return self.path / "evaluations.npz"

    @property
    def logs(self) -> Path:
        """``logs/``: progress.csv and TensorBoard events."""
        return self.path / LOGS

    @property
    def progress(self) -> Path:
        """``logs/progress.csv``: the training log of the last segment."""
        return self.path / LOGS / PROGRESS

    @property
    def env_steps_by_node(self) -> Path:
        """``logs/env_steps_by_node.json``: an RLlib run's env steps per Ray node."""
        return self.path / LOGS / "env_steps_by_node.json"

    @property
    def monitor(self) -> Path:
        """The training envs' monitor files (SB3's Monitor)."""
        return self.path / "monitor"

    @property
    def plots(self) -> Path:
        """The training figures."""
        return self.path / "plots"

    @property
    def rounds(self) -> Path:
        """A distillation's rounds."""
        return self.path / "rounds.csv"

    @property
    def best_policy(self) -> Path:
        """The best model's policy file (with best_model.json)."""
        return self.path / f"best_model{WEIGHTS}"

    @property
    def final_policy(self) -> Path:
        """The last model's policy file (with final_model.json)."""
        return self.path / f"final_model{WEIGHTS}"

    @property
    def shipped_policy(self) -> Path:
        """A shipped agent's policy file (results/<Id>/policy.safetensors, with policy.json)."""
        return self.path / SHIPPED_POLICY

    @property
    def best_zip(self) -> Path:
        """SB3's best model (EvalCallback names it, given best_model_save_path=path)."""
        return self.path / "best_model.zip"

    @property
    def final_zip(self) -> Path:
        """SB3's last model."""
        return self.path / "final_model.zip"

    @property
    def latest_zip(self) -> Path:
        """``checkpoints/latest.zip``: an older SB3 run's checkpoint, a pickle (``--resume`` reads it if trusted)."""
        return self.path / "checkpoints" / "latest.zip"

    @property
    def best_dir(self) -> Path:
        """RLlib's checkpoint folder of the best model."""
        return self.path / "best_model"

    @property
    def final_dir(self) -> Path:
        """RLlib's checkpoint folder of the last model."""
        return self.path / "final_model"

    @property
    def latest_dir(self) -> Path:
        """``checkpoints/latest/``: the newest checkpoint, for ``--resume`` (SB3's as data: STATE_JSON...; RLlib's)."""
        return self.path / "checkpoints" / "latest"

    def is_run(self) -> bool:
        """Whether the folder holds a config.json (a run's, or a shipped agent's)."""
        return self.config.is_file()

    def log_folder(self) -> Path:
        """``logs/``, or the folder itself where a shipped agent's folder keeps its logs beside config.json."""
        flat = not self.logs.is_dir() and (self.path / PROGRESS).is_file()
        return self.path if flat else self.logs

    def progress_parts(self) -> list[Path]:
        """progress-1.csv, progress-2.csv, ... (the segments before each resume), then progress.csv."""
        logs = self.log_folder()
        parts = [p for p in logs.glob("progress-*.csv") if p.stem.rsplit("-", 1)[1].isdigit()]
        parts.sort(key=lambda p: int(p.stem.rsplit("-", 1)[1]))
        return parts + [logs / PROGRESS]

    def keep_earlier_progress(self) -> None:
        """SB3 starts progress.csv afresh on a resume: keep the earlier segment as progress-<n>.csv."""
        current = self.progress
        if current.exists():
            n = 1
            while (self.logs / f"progress-{n}.csv").exists():
                n += 1
            current.rename(self.logs / f"progress-{n}.csv")


def new_run_dir(root: str | Path, env_id: str) -> Path:
    """A new, empty run folder ``root/<env_id>/<timestamp>``."""
    from visualenv.files import make_dir

    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    run = make_dir(Path(root) / env_id) / stamp
    run.mkdir(exist_ok=False)
    return run


def _folder(run: str | Path | RunFolder) -> RunFolder:
    return run if isinstance(run, RunFolder) else RunFolder(run)


# -- reading and writing --------------------------------------------------------------------------------------------


def _write_json(path: Path, value: dict[str, Any]) -> None:
    path.write_text(json.dumps(value, indent=2) + "\n", encoding="utf-8")


def write_config(run: str | Path | RunFolder, record: dict[str, Any]) -> Path:
    """Write config.json: `record` in the current format (format and version set), checked first."""
    folder = _folder(run)
    record = check_record({"format": FORMAT, "format_version": FORMAT_VERSION, **record}, str(folder.config))
    _write_json(folder.config, record)
    return folder.config


def read_config(run: str | Path | RunFolder) -> dict[str, Any]:
    """config.json in the current format (an older run's migrated, see :func:`migrate`), its settings checked."""
    folder = _folder(run)
    if not folder.is_run():
        raise RunFolderError(
            f"{folder.path} is not a run folder of `visualenv train` nor `visualenv distill` (no {folder.config.name})"
        )
    record = migrate(read_json_as(folder.config, RunFolderError), where=str(folder.config)).record
    assert record is not None
    return record


@dataclass
class RunClock:
    """A run's training time (results.json's ``wall_time_s``): `earlier` seconds its checkpoint recorded, for a
    resumed run (the time after that checkpoint, redone on resuming, is not counted), and this segment's."""

    earlier: float = 0.0
    started: float = field(default_factory=time.perf_counter)

    def segment(self) -> float:
        return time.perf_counter() - self.started

    def elapsed(self) -> float:
        return self.earlier + self.segment()


def recorded_seconds(value: Any) -> float:
    """A training time a checkpoint recorded, in seconds: 0 where it recorded none or something other than a finite
    number from 0 (a checkpoint from before the time was kept, or an edited one), never an error."""
    return max(float(value), 0.0) if finite_number(value) else 0.0


def write_results(run: str | Path | RunFolder, results: dict[str, Any]) -> Path:
    """Write results.json, its figures checked first."""
    folder = _folder(run)
    _write_json(folder.results, check_results(results, str(folder.results)))
    return folder.results


def record_run(
    run: str | Path | RunFolder,
    config: Any,
    spec_path: str,
    *,
    backend: str,
    resume: bool = False,
    changes: dict[str, Any] | None = None,
    extra: dict[str, Any] | None = None,
) -> None:
    """config.json of a new run (the command, `config`'s settings, the versions, `extra` keys); a resumed run's
    keeps its record, takes the settings now in force and appends the command and the changed hyperparameters."""
    from visualenv.spec.loader import spec_identity
    from visualenv.versions import versions

    folder = _folder(run)
    settings_now = asdict(config) if is_dataclass(config) and not isinstance(config, type) else dict(config)
    command = shlex.join(sys.argv)
    if resume:
        record = read_config(folder)
        record["config"] = settings_now
        record.setdefault("resumes", []).append({"command": command, "hyperparams": dict(changes or {})})
    else:
        record = {
            "backend": backend,
            "command": command,
            "config": settings_now,
            "versions": versions(),
            "spec_path": spec_path,
            **(extra or {}),
        }
    record.setdefault("spec", spec_identity(spec_path))  # the spec's id and sha256, which --resume checks
    write_config(folder, record)


@dataclass
class Run:
    """A run folder's config.json and results.json in the current format."""

    folder: RunFolder | None
    record: dict[str, Any] | None  # config.json; None where the folder has none (a model file's folder)
    results: dict[str, Any] | None  # results.json; None where the folder has none
    note: str | None = None  # what an older run does not record: why replaying its final evaluation may differ

    @property
    def config(self) -> dict[str, Any]:
        return self.record["config"] if self.record else {}


def read_run(run: str | Path | RunFolder) -> Run:
    """The config.json and results.json of `run` that exist, migrated to the current format and checked."""
    folder = _folder(run)
    record = read_json_as(folder.config, RunFolderError) if folder.is_run() else None
    results = read_json_as(folder.results, RunFolderError) if folder.results.is_file() else None
    return migrate(record, results, folder, where=str(folder.path))


# -- older runs -----------------------------------------------------------------------------------------------------


def legacy_eval_seed(train_seed: int) -> int:
    """The one evaluation stream of runs made before selection and report were split."""
    return train_seed + LEGACY_EVAL_OFFSET


def migrate(record: Any, results: Any = None, folder: RunFolder | None = None, *, where: str = "run folder") -> Run:
    """A run's config.json `record` and `results` (each may be None) in the current format, checked.

    The older formats this reads (config.json without ``format_version`` is format 1):

    * every run before format 2 has no ``format``, ``format_version`` nor, except RLlib runs (``"rllib"``), a
      ``backend``: a distillation's config has ``algo`` ``"dagger"``, any other run is SB3's;
    * SB3 runs before ``pin``, ``batched``, ``workers`` and ``render_device`` existed lack them; they resume as
      the defaults then were: pinned, one process per env, the spec's render device. RLlib runs before ``pin`` and
      ``batched`` likewise; distillations before ``--student`` lack ``student`` (none); SB3 runs before
      ``--augment`` (format 2 included) lack ``augment`` (none);
    * results.json before ``eval_seed`` (SB3 and RLlib runs): the final evaluation ran on the env of the periodic
      evaluations, seeded the run's seed + 10000 at the start of the run's last segment (its start or latest
      ``--resume``), reset once then and ``eval_episodes + 1`` times by each periodic evaluation since. ``eval_seed``
      becomes that seed and ``resets_before`` those resets, counted from evaluations.npz and the segment's
      progress.csv; where they cannot be counted (an RLlib run, a lost log) ``note`` says so;
    * results.json of shipped agents re-evaluated before ``evaluated`` existed have ``reevaluated``: dropped.

    A config.json of a later format than :data:`FORMAT_VERSION` is refused: this version cannot know its meaning.
    """
    older = isinstance(record, dict) and "format_version" not in record
    if record is not None:
        record = _migrated_record(record, str(folder.config) if folder else where)  # an error names the file
    note = None
    if results is not None:
        results = check_results(
            {k: v for k, v in results.items() if k != "reevaluated"} if isinstance(results, dict) else results,
            str(folder.results) if folder else where,
        )
        if record is not None and "eval_seed" not in results:
            if not older:
                raise RunFolderError(f"{where}: results.json has no eval_seed, which every run of format 2 records")
            results, note = _with_legacy_seed(results, record, folder)
    return Run(folder, record, results, note)


def _migrated_record(record: Any, where: str) -> dict[str, Any]:
    if not isinstance(record, dict) or not isinstance(record.get("config"), dict):
        raise RunFolderError(f"{where}: not the config.json of a visualenv run (no 'config' mapping of settings)")
    version = record.get("format_version", 1)
    if isinstance(version, int) and not isinstance(version, bool) and version > FORMAT_VERSION:
        raise RunFolderError(
            f"{where}: written by a later visualenv (run folder format {version}); this one reads "
            f"formats up to {FORMAT_VERSION}: upgrade visualenv"
        )
    record = {**record, "config": dict(record["config"])}
    if version == 1:
        backend = record.get("backend") or ("distill" if record["config"].get("algo") == "dagger" else "sb3")
        record = {"format": FORMAT, "format_version": FORMAT_VERSION, "backend": backend, **record}
    # a setting added since (format 1: pin and others; format 2: augment) takes the value older runs had
    record["config"] = {**ADDED.get(str(record.get("backend")), {}), **record["config"]}
    return check_record(record, where)


def _with_legacy_seed(
    results: dict[str, Any], record: dict[str, Any], folder: RunFolder | None
) -> tuple[dict[str, Any], str | None]:
    config = record["config"]
    results = {**results, "eval_seed": legacy_eval_seed(config["seed"])}
    periodic = _periodic_evaluations_in_last_segment(folder) if folder and record["backend"] == "sb3" else None
    resets = None if periodic is None else 1 + periodic * (config["eval_episodes"] + 1)
    if resets is None or resets > MAX_RESETS_BEFORE:
        why = (
            "cannot be counted" if resets is None else f"are {resets:,} resets, more than {MAX_RESETS_BEFORE:,} replay"
        )
        return results, (
            f"results.json predates eval_seed: the periodic evaluations before its final one (on the same env) {why}, "
            "so its episodes differ"
        )
    return {**results, "resets_before": resets}, None


def load_evaluations(run: str | Path | RunFolder) -> dict[str, np.ndarray] | None:
    """evaluations.npz's arrays; None where it is missing, unreadable or its arrays exceed MAX_EVALUATIONS_BYTES."""
    path = _folder(run).evaluations
    try:
        with zipfile.ZipFile(path) as archive:
            if sum(member.file_size for member in archive.infolist()) > MAX_EVALUATIONS_BYTES:
                return None
        with np.load(path) as saved:  # without pickles
            return {name: saved[name] for name in saved.files}
    except (OSError, ValueError, MemoryError, zipfile.BadZipFile):
        return None


def _periodic_evaluations_in_last_segment(folder: RunFolder) -> int | None:
    """Evaluations (evaluations.npz) since the last segment of the run started; None if its start is unknown."""
    timesteps = (load_evaluations(folder) or {}).get("timesteps", np.zeros(0))
    start = _last_segment_start(folder)
    try:
        return None if start is None else int(np.sum(np.asarray(timesteps, dtype=np.float64) > start))
    except (TypeError, ValueError):  # an array that holds no step numbers
        return None


def _last_segment_start(folder: RunFolder) -> int | None:
    """The step the run's last segment started at, from its progress.csv (SB3's on-policy rows: iterations and
    total steps)."""
    progress = folder.log_folder() / PROGRESS
    if not progress.is_file():
        return None
    try:
        with progress.open(newline="") as f:
            rows = [
                (float(r["time/iterations"]), float(r["time/total_timesteps"]))
                for r in itertools.islice(csv.DictReader(f), 1000)  # the first rows say where the segment started
                if r.get("time/iterations") and r.get("time/total_timesteps")
            ]
    except (OSError, KeyError, ValueError, csv.Error):
        return None
    if len(rows) < 2 or rows[1][0] == rows[0][0]:
        return None
    (i1, t1), (i2, t2) = rows[:2]
    per_iteration = (t2 - t1) / (i2 - i1)
    return round(t1 - i1 * per_iteration)
