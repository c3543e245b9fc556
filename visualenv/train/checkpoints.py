"""What `visualenv train --resume` reads: an SB3 run's training state as data, and the checks made before any of it.

``train`` saves the state of its model to ``checkpoints/latest/`` (:attr:`RunFolder.latest_dir`, where an RLlib run
keeps its own checkpoint), a folder swapped in whole, so a run killed while saving keeps the previous one:

* ``weights.safetensors``: the tensors: the state dict of each torch object SB3's own ``save`` keeps, under its
  name (``policy/<key>``, a tensor the policy lists under several names once), each optimizer's per-parameter
  state (``policy.optimizer/state/<index>/exp_avg``, ...) and SAC's entropy coefficient (``variables/log_ent_coef``);
* ``state.json``: :data:`FORMAT` and :data:`FORMAT_VERSION`, the algorithm, SB3's counters (``num_timesteps``,
  ``_n_updates``, ...), each optimizer's ``param_groups`` and any state that is not a tensor, the recent episodes
  behind ``rollout/ep_rew_mean``, the replay buffer's ``pos`` and ``full``, and the run's training time so far
  (``wall_time_s``: a resumed run's results.json adds it to its own);
* ``replay_buffer.npz`` (off-policy algorithms: SAC, DQN): the buffer's filled rows (observations, next
  observations unless ``optimize_memory_usage``, actions, rewards, dones, timeouts), read with ``allow_pickle=False``;
  ``--augment``'s buffer adds the final frames of episodes cut by a timeout (``final_observations``, ``final_slots``).

``--resume`` builds a new model from the run's config.json as ``train`` does and loads this state into it, each
name, shape, type and value checked against that model first: nothing is unpickled, and a checkpoint that does not
fit is an error naming what differs. A learning-rate schedule, being a hyperparameter, is rebuilt from config.json.
The random generators restart from the run's seed, as SB3's ``load`` makes them.

Before anything is read or written, :func:`resume_checkpoint` checks that the run was trained on the spec given
(the id and sha256 config.json records) and that it has a checkpoint; an older run's ``checkpoints/latest.zip`` and
an RLlib run's checkpoint folder are pickles, which it accepts only with ``trust_pickle``.
"""

from __future__ import annotations

import json
import shutil
from operator import attrgetter
from pathlib import Path
from typing import Any

import numpy as np

from visualenv.compat.sb3 import episode_window, set_training_counters, state_names, training_counters
from visualenv.errors import ConfigError, VisualEnvError
from visualenv.files import check_format, read_json_as
from visualenv.train.model_files import PickleRefused
from visualenv.train.policy_format import weights_of
from visualenv.spec.loader import spec_identity
from visualenv.train.run_folder import (
    STATE_JSON,
    STATE_REPLAY,
    STATE_WEIGHTS,
    RunFolder,
    RunFolderError,
    read_config,
    recorded_seconds,
)
from visualenv.train.run_settings import finite_number

FORMAT = "visualenv-sb3-checkpoint"
FORMAT_VERSION = 1
MAX_STATE_JSON = 16 * 2**20  # state.json holds counters and optimizer settings: kilobytes
REPLAY_FIELDS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")
MAX_COUNTER = 10**15


class CheckpointError(ConfigError):
    """A checkpoint that does not fit the run's model, or that is not a checkpoint of this format."""


# -- before resuming --------------------------------------------------------------------------------------------------


def sb3_checkpoint(folder: RunFolder) -> Path | None:
    """The SB3 run's newest checkpoint: its data folder (or the one it was replacing when a save was interrupted), else
    an older run's ``checkpoints/latest.zip``; None if it has neither."""
    latest = folder.latest_dir
    for path in (latest, latest.with_name(latest.name + ".old")):
        if (path / STATE_JSON).is_file():
            return path
    return folder.latest_zip if folder.latest_zip.is_file() else None


def resume_checkpoint(
    folder: RunFolder, spec_path: str | Path, checkpoint: Path | None, *, backend: str, trust_pickle: bool
) -> Path:
    """`checkpoint`, once the run is known to be one of the spec at `spec_path` and `checkpoint` loadable: an SB3
    checkpoint of data always; a pickle (an older SB3 run's zip, any RLlib checkpoint) only with `trust_pickle`.
    Raises before anything is read or written."""
    check_resumed_spec(folder, spec_path)
    if checkpoint is None:
        names = [folder.latest_dir, folder.latest_zip] if backend == "sb3" else [folder.latest_dir]
        looked = " nor ".join(str(p.relative_to(folder.path)) for p in names)
        raise RunFolderError(
            f"{folder.path} has no checkpoint to resume from (no {looked}); nothing in it was changed. "
            "Start a new run instead"
        )
    if not (backend == "sb3" and checkpoint.is_dir()) and not trust_pickle:
        kind = "an RLlib checkpoint folder" if checkpoint.is_dir() else "an SB3 model"
        raise PickleRefused(
            f"{checkpoint} is {kind}: a pickle-based file, and loading it can run any code it holds. If you trust "
            "where it came from, pass --trust-pickle (Python: trust_pickle=True) to resume from it (docs/security.md)"
        )
    return checkpoint


def check_resumed_spec(folder: RunFolder, spec_path: str | Path) -> None:
    """That the run was trained on the spec at `spec_path`: the id and sha256 its config.json records (an older run's
    that records none: those of the spec file it names, as it is now); else an error naming both."""
    from visualenv.env.registration import resolve

    given, record = spec_identity(spec_path), read_config(folder)
    trained = record.get("spec")
    if trained is None:
        try:
            trained = spec_identity(resolve(record["config"]["spec"]))
        except (VisualEnvError, OSError):
            raise RunFolderError(
                f"{folder.path} records no hash of its spec, and {record['config']['spec']!r}, the spec it names, no "
                "longer loads: cannot tell whether it was trained on this spec; start a new run"
            ) from None
    if trained != given:
        other = "another version of " if trained.get("id") == given["id"] else ""
        raise RunFolderError(
            f"{folder.path} was trained on {other}{trained.get('id')} (spec sha256 {str(trained.get('sha256'))[:12]}), "
            f"not on {spec_path} ({given['id']}, sha256 {given['sha256'][:12]}): resume it with the spec it was "
            "trained on, or start a new run"
        )


# -- saving -----------------------------------------------------------------------------------------------------------


def save_state(model: Any, folder: RunFolder, algorithm: str, *, wall_time_s: float | None = None) -> Path:
    """Write `model`'s training state to ``checkpoints/latest/`` (the module's docstring lists it); `wall_time_s`: the
    run's training time up to now."""
    import torch
    from safetensors.torch import save_file

    state_dicts, variables = state_names(model)
    tensors: dict[str, Any] = {}
    optimizers: dict[str, Any] = {}
    for name in state_dicts:
        target = attrgetter(name)(model)
        if isinstance(target, torch.optim.Optimizer):
            saved = target.state_dict()
            scalars: dict[str, dict[str, Any]] = {}
            for index, entries in saved["state"].items():
                for key, value in entries.items():
                    if torch.is_tensor(value):
                        tensors[f"{name}/state/{index}/{key}"] = value.detach().cpu().contiguous().clone()
                    else:
                        scalars.setdefault(str(index), {})[key] = value
            optimizers[name] = {"param_groups": saved["param_groups"], "state": scalars}
        else:
            tensors.update({f"{name}/{key}": value for key, value in weights_of(target, half=False).items()})
    for name in variables:
        value = attrgetter(name)(model)
        if value is not None:
            tensors[f"variables/{name}"] = value.detach().cpu().contiguous().clone()
    buffer = getattr(model, "replay_buffer", None)
    state = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "algorithm": algorithm,
        "counters": {name: _plain(value) for name, value in training_counters(model).items()},
        "optimizers": optimizers,
        "episodes": [_scalars(entry) for entry in model.ep_info_buffer or []],
        "successes": [bool(s) for s in model.ep_success_buffer or []],
        "replay_buffer": None if buffer is None else {"pos": int(buffer.pos), "full": bool(buffer.full)},
        "wall_time_s": None if wall_time_s is None else round(wall_time_s, 1),
    }
    latest = folder.latest_dir
    fresh, old = latest.with_name(latest.name + ".saving"), latest.with_name(latest.name + ".old")
    shutil.rmtree(fresh, ignore_errors=True)
    fresh.mkdir(parents=True)
    save_file(tensors, str(fresh / STATE_WEIGHTS), metadata={"format": FORMAT})
    if buffer is not None:
        np.savez(fresh / STATE_REPLAY, **_replay_arrays(buffer), **_kept_arrays(buffer))
    (fresh / STATE_JSON).write_text(json.dumps(state, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    if latest.exists():
        shutil.rmtree(old, ignore_errors=True)
        latest.rename(old)
    fresh.rename(latest)
    shutil.rmtree(old, ignore_errors=True)
    return latest


def _plain(value: Any) -> Any:
    """A numpy scalar as the Python number it holds (JSON takes those)."""
    return value.item() if isinstance(value, np.generic) else value


def _scalars(entry: dict[str, Any]) -> dict[str, Any]:
    """An episode's record (Monitor's ``r``, ``l``, ``t``...) with the values JSON holds: numbers, flags, text."""
    plain = {key: _plain(value) for key, value in entry.items()}
    return {key: value for key, value in plain.items() if isinstance(value, (bool, int, float, str))}


def _replay_arrays(buffer: Any) -> dict[str, np.ndarray]:
    """The buffer's filled rows of each array, by name (``observations.<key>`` for a dict of observations)."""
    arrays = {}
    for field in REPLAY_FIELDS:
        value = getattr(buffer, field, None)
        if isinstance(value, dict):
            arrays.update({f"{field}.{key}": array[: _rows(buffer, field)] for key, array in value.items()})
        elif value is not None:
            arrays[field] = value[: _rows(buffer, field)]
    return arrays


def _kept_arrays(buffer: Any) -> dict[str, np.ndarray]:
    """What a buffer keeps besides SB3's rows (`--augment`'s buffer: the final frames of episodes cut by a timeout)."""
    kept = getattr(buffer, "kept_arrays", None)
    return kept() if kept is not None else {}


def _rows(buffer: Any, field: str) -> int:
    """How many rows of `field` hold data: all once the buffer is full, else up to pos; with
    ``optimize_memory_usage`` row pos of the observations too (the last transition's next observation)."""
    if buffer.full:
        return int(buffer.buffer_size)
    extra = field == "observations" and getattr(buffer, "next_observations", None) is None
    return min(int(buffer.pos) + extra, int(buffer.buffer_size))


# -- loading ----------------------------------------------------------------------------------------------------------


def load_state(model: Any, checkpoint: Path, algorithm: str) -> None:
    """Load the training state in `checkpoint` (a folder :func:`save_state` wrote) into `model`, a new model of the
    run's config; a checkpoint that does not fit it is a :class:`CheckpointError` naming what differs."""
    import torch

    state = _read_state(checkpoint / STATE_JSON)
    if state.get("algorithm") != algorithm:
        raise CheckpointError(
            f"{checkpoint}: a checkpoint of {state.get('algorithm')!r}, and this run trains {algorithm}"
        )
    tensors = _read_tensors(checkpoint / STATE_WEIGHTS, _most_bytes(model))
    where = checkpoint / STATE_WEIGHTS
    state_dicts, variables = state_names(model)
    optimizers = _mapping(state.get("optimizers"), f"{checkpoint / STATE_JSON}: optimizers")
    if sorted(optimizers) != sorted(n for n in state_dicts if isinstance(attrgetter(n)(model), torch.optim.Optimizer)):
        raise CheckpointError(f"{checkpoint / STATE_JSON}: optimizers {sorted(optimizers)} are not this model's")
    used: set[str] = set()
    for name in state_dicts:
        target = attrgetter(name)(model)
        prefix = f"{name}/"
        own = {k[len(prefix) :]: v for k, v in tensors.items() if k.startswith(prefix)}
        used.update(prefix + k for k in own)
        if isinstance(target, torch.optim.Optimizer):
            target.load_state_dict(_optimizer_state(target, own, optimizers[name], f"{where}: {name}"))
        else:
            _check_tensors(own, weights_of(target, half=False), f"{where}: {name}")
            target.load_state_dict(own, strict=False)  # the names a shared tensor also has load with it
    for name in variables:
        current, key = attrgetter(name)(model), f"variables/{name}"
        if current is not None:
            _check_tensors({key: tensors.get(key)}, {key: current.detach()}, str(where))
            current.data.copy_(tensors[key])
            used.add(key)
    if set(tensors) - used:
        raise CheckpointError(
            f"{where}: tensors this model does not have: {', '.join(sorted(set(tensors) - used)[:5])}"
        )
    _load_counters(model, state, checkpoint / STATE_JSON)
    _load_replay(model, state.get("replay_buffer"), checkpoint)


def saved_wall_time(checkpoint: Path) -> float:
    """The training time a data checkpoint recorded (seconds); 0 for a pickled one, or one saved before it was
    recorded."""
    if not checkpoint.is_dir():
        return 0.0
    return recorded_seconds(_read_state(checkpoint / STATE_JSON).get("wall_time_s"))


def _read_state(path: Path) -> dict[str, Any]:
    state = read_json_as(path, CheckpointError, max_bytes=MAX_STATE_JSON)
    return check_format(state, path, "a checkpoint", FORMAT, FORMAT_VERSION, CheckpointError)


def _most_bytes(model: Any) -> int:
    """What the weights file of `model` can hold at most: its policy (target networks included), an optimizer's two
    moments for each of its weights, a tensor or two besides; the file's size is checked against it before reading."""
    policy = sum(p.numel() * p.element_size() for p in model.policy.state_dict().values())
    return 4 * policy + 2**20


def _read_tensors(path: Path, most: int) -> dict[str, Any]:
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    try:
        size = path.stat().st_size
        if size > most:
            raise CheckpointError(
                f"{path}: {size / 2**20:.1f} MiB, more than this run's model and optimizers hold "
                f"({most / 2**20:.1f} MiB at most): not a checkpoint of this run"
            )
        return load_file(str(path))
    except (SafetensorError, OSError, ValueError) as exc:
        raise CheckpointError(f"{path}: not a safetensors file this checkpoint can use ({exc})") from None


def _mapping(value: Any, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise CheckpointError(f"{where}: expected a mapping, got {type(value).__name__}")
    return value


def _check_tensors(saved: dict[str, Any], expected: dict[str, Any], where: str) -> None:
    """`saved` has exactly the names of `expected`, each of its shape and dtype, and floats that are finite."""
    import torch

    missing, unknown = sorted(set(expected) - set(saved)), sorted(set(saved) - set(expected))
    if missing or unknown:
        raise CheckpointError(
            f"{where}: does not fit this run's model: "
            + "; ".join(
                f"{what} {', '.join(names[:5])}" for what, names in (("lacks", missing), ("has no", unknown)) if names
            )
        )
    for name, want in expected.items():
        have = saved[name]
        if have is None or have.shape != want.shape or have.dtype != want.dtype:
            got = "nothing" if have is None else f"{have.dtype} {list(have.shape)}"
            raise CheckpointError(f"{where}: {name}: expected {want.dtype} {list(want.shape)}, got {got}")
        if have.is_floating_point() and not bool(torch.isfinite(have).all()):
            raise CheckpointError(f"{where}: {name}: holds NaN or infinite values")


def _optimizer_state(optimizer: Any, saved: dict[str, Any], record: Any, where: str) -> dict[str, Any]:
    """The optimizer's state dict from its saved tensors (by parameter index) and the JSON of the rest, checked against
    `optimizer`: the same parameter groups, each value of the type it has now, per-parameter tensors of its shape."""
    import torch

    record = _mapping(record, where)
    current = optimizer.state_dict()
    groups = record.get("param_groups")
    if not isinstance(groups, list) or len(groups) != len(current["param_groups"]):
        raise CheckpointError(f"{where}: param_groups: expected {len(current['param_groups'])} groups")
    shapes = {
        index: param.shape
        for group_record, group in zip(current["param_groups"], optimizer.param_groups)
        for index, param in zip(group_record["params"], group["params"])
    }
    param_groups = [
        _conform(g, c, f"{where}: param_groups[{i}]") for i, (g, c) in enumerate(zip(groups, current["param_groups"]))
    ]
    state: dict[int, dict[str, Any]] = {}
    for key, tensor in saved.items():
        parts = key.split("/")
        if len(parts) != 3 or parts[0] != "state" or not parts[1].isdigit() or int(parts[1]) not in shapes:
            raise CheckpointError(f"{where}: {key}: not a parameter's state of this optimizer")
        index = int(parts[1])
        if tensor.dim() and tensor.shape != shapes[index] or not tensor.is_floating_point():
            raise CheckpointError(
                f"{where}: {key}: expected a float scalar or {list(shapes[index])}, got {list(tensor.shape)}"
            )
        if not bool(torch.isfinite(tensor).all()):
            raise CheckpointError(f"{where}: {key}: holds NaN or infinite values")
        state.setdefault(index, {})[parts[2]] = tensor
    for text, entries in _mapping(record.get("state", {}), f"{where}: state").items():
        for name, value in _mapping(entries, f"{where}: state.{text}").items():
            if not text.isdigit() or int(text) not in shapes or not finite_number(value):
                raise CheckpointError(f"{where}: state.{text}.{name}: expected a number of a parameter's state")
            state.setdefault(int(text), {})[name] = value
    return {"state": state, "param_groups": param_groups}


def _conform(saved: Any, like: Any, where: str) -> Any:
    """`saved` (read from JSON) as a value of `like`'s kind: a mapping of the same keys, a tuple from a list, a finite
    number for a number, true/false or null for a flag, the same text for a text; else an error."""
    if isinstance(like, dict):
        saved = _mapping(saved, where)
        if sorted(saved) != sorted(like):
            raise CheckpointError(f"{where}: expected the keys {sorted(like)}, got {sorted(saved)}")
        return {key: _conform(saved[key], like[key], f"{where}.{key}") for key in like}
    if isinstance(like, (list, tuple)):
        if not isinstance(saved, list) or len(saved) != len(like):
            raise CheckpointError(f"{where}: expected a list of {len(like)}, got {saved!r:.80}")
        items = [_conform(s, c, f"{where}[{i}]") for i, (s, c) in enumerate(zip(saved, like))]
        return tuple(items) if isinstance(like, tuple) else items
    if like is None or isinstance(like, bool):
        ok = saved is None or isinstance(saved, bool)
    elif isinstance(like, (int, float)):
        ok = finite_number(saved) and (isinstance(saved, int) or not isinstance(like, int))
    else:
        ok = isinstance(saved, str) and isinstance(like, str)
    if not ok:
        raise CheckpointError(f"{where}: expected a value like {like!r}, got {saved!r:.80}")
    return saved


def _load_counters(model: Any, state: dict[str, Any], where: Path) -> None:
    from collections import deque

    counters = _mapping(state.get("counters"), f"{where}: counters")
    current = training_counters(model)
    if sorted(counters) != sorted(current):
        raise CheckpointError(f"{where}: counters: expected {sorted(current)}, got {sorted(counters)}")
    for name, value in counters.items():
        integer = isinstance(current[name], int) and not isinstance(current[name], bool)
        if not finite_number(value) or (integer and not (isinstance(value, int) and 0 <= value <= MAX_COUNTER)):
            raise CheckpointError(
                f"{where}: counters.{name}: expected {'a count' if integer else 'a number'}, got {value!r:.80}"
            )
    episodes, successes, window = state.get("episodes", []), state.get("successes", []), episode_window(model)
    if not (isinstance(episodes, list) and len(episodes) <= window and all(_episode(e) for e in episodes)):
        raise CheckpointError(f"{where}: episodes: expected up to {window} episodes' returns, lengths and times")
    if not (isinstance(successes, list) and len(successes) <= window and all(isinstance(s, bool) for s in successes)):
        raise CheckpointError(f"{where}: successes: expected up to {window} true/false")
    set_training_counters(model, counters)
    model.ep_info_buffer, model.ep_success_buffer = deque(episodes, maxlen=window), deque(successes, maxlen=window)


def _episode(entry: Any) -> bool:
    """An entry of SB3's recent episodes (Monitor's ``r``, ``l``, ``t`` and the like): texts to numbers or flags."""
    return isinstance(entry, dict) and all(
        isinstance(k, str) and (finite_number(v) or isinstance(v, (bool, str))) for k, v in entry.items()
    )


def _load_replay(model: Any, record: Any, checkpoint: Path) -> None:
    """The saved rows into the new model's replay buffer, their names, shapes and dtypes checked from the file's
    headers before any array is read."""
    buffer, path = getattr(model, "replay_buffer", None), checkpoint / STATE_REPLAY
    if buffer is None:
        if record is not None:
            raise CheckpointError(f"{checkpoint / STATE_JSON}: a replay buffer, and this run's algorithm keeps none")
        return
    record = _mapping(record, f"{checkpoint / STATE_JSON}: replay_buffer")
    pos, full = record.get("pos"), record.get("full")
    if not (
        isinstance(pos, int) and not isinstance(pos, bool) and 0 <= pos < buffer.buffer_size and isinstance(full, bool)
    ):
        raise CheckpointError(
            f"{checkpoint / STATE_JSON}: replay_buffer: expected pos from 0 to {buffer.buffer_size - 1} and full "
            f"true/false, got {record!r:.120} (a resumed run keeps its buffer_size)"
        )
    buffer.pos, buffer.full = pos, full
    targets = _replay_arrays(buffer)  # views of the new buffer's rows that the saved ones fill
    kept = _kept_arrays(buffer)  # their number varies: checked against the buffer's bounds
    headers = _npz_headers(path, sorted([*targets, *kept]))
    if kept:
        _check_kept(headers, buffer, path)
    for name, target in targets.items():
        if headers[name] != (target.shape, target.dtype):
            shape, dtype = headers[name]
            raise CheckpointError(
                f"{path}: {name}: expected {target.dtype} {list(target.shape)}, got {dtype} {list(shape)}"
            )
    with np.load(path, allow_pickle=False) as saved:
        for name, target in targets.items():
            target[...] = saved[name]
        if kept:
            slots = saved["final_slots"]
            if ((slots < 0) | (slots >= np.array(buffer.has_final.shape))).any():
                raise CheckpointError(f"{path}: final_slots: a slot outside the buffer's {buffer.has_final.shape}")
            buffer.restore_kept(saved["final_observations"], slots)


def _check_kept(headers: dict[str, tuple[tuple[int, ...], np.dtype]], buffer: Any, path: Path) -> None:
    """The final frames' shapes and types, and their number within the buffer's slots, before they are read."""
    (frames, frame_type), (slots, slot_type) = headers["final_observations"], headers["final_slots"]
    count = frames[0] if frames else -1
    if not (
        frames[1:] == tuple(buffer.obs_shape)
        and frame_type == buffer.observations.dtype
        and slots == (count, 2)
        and slot_type == np.int64
        and count <= buffer.has_final.size
    ):
        raise CheckpointError(
            f"{path}: final_observations {list(frames)} and final_slots {list(slots)}: expected at most "
            f"{buffer.has_final.size} frames of {buffer.observations.dtype} {list(buffer.obs_shape)} and their slots"
        )


def _npz_headers(path: Path, names: list[str]) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Each array of an .npz that holds the arrays `names` and no other: its shape and dtype, from its header alone."""
    import zipfile

    from numpy.lib import format as npy

    headers = {}
    try:
        with zipfile.ZipFile(path) as archive:
            members = archive.namelist()
            if sorted(members) != sorted(f"{name}.npy" for name in names):
                raise CheckpointError(f"{path}: holds {sorted(members)[:8]}, and this run's replay buffer {names}")
            for member in members:
                with archive.open(member) as f:
                    version = npy.read_magic(f)
                    read = {(1, 0): npy.read_array_header_1_0, (2, 0): npy.read_array_header_2_0}.get(version)
                    if read is None:
                        raise ValueError(f"{member}: not a .npy of format 1.0 or 2.0")
                    shape, _, dtype = read(f)
                headers[member.removesuffix(".npy")] = (tuple(shape), np.dtype(dtype))
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise CheckpointError(f"{path}: not a replay buffer of this format ({exc})") from None
    return headers
