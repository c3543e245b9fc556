"""Policy files that are data: ``policy.safetensors`` (the weights) beside ``policy.json`` (what builds the network).

Loading one reads tensors and JSON and nothing else: no pickle, no class or function
named by the file. ``policy.json`` holds:

* ``format``, ``format_version``: ``"visualenv-policy"``, 1
* ``backend`` (``sb3`` or ``rllib``), ``algorithm`` (``ppo``, ``a2c``, ``dqn``, ``sac``)
* ``policy``: the policy kind, a key of visualenv's fixed list (:mod:`visualenv.train.policy_kinds`)
* ``arguments``: the network's constructor arguments as JSON; classes among them by allowed names
* ``observation_space``, ``action_space``: Gymnasium spaces as JSON (:func:`space_to_data`)
* ``frame_stack``: the frames the policy sees at once (null where unknown), ``spec``: the env's id and
  the sha256 of its spec file (null where unknown), ``dtype`` of the weights, ``machine``: the
  machine and versions that wrote the file

The weights are the module's state dict in safetensors, each shared tensor stored
once (SB3's actor-critic lists its shared features extractor under three names), so
``safetensors.torch.load_model`` reads them into a network built from the JSON::

    from safetensors.torch import load_model
    load_model(policy, "results/Goalie-v0/policy.safetensors")  # float16 weights into a float32 network
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from visualenv.files import check_format, read_json_as
from visualenv.train.policy_check import check_against, check_arguments, check_finite, check_space_size, on_meta
from visualenv.train.policy_kinds import PolicyFileError, build_rllib_module, build_sb3_policy, rllib_kind, sb3_kind

FORMAT, FORMAT_VERSION = "visualenv-policy", 1
WEIGHTS, META = ".safetensors", ".json"
#: the dtypes a space may have in a policy file
SPACE_DTYPES = (
    "uint8",
    "int8",
    "int16",
    "int32",
    "int64",
    "uint16",
    "uint32",
    "uint64",
    "float16",
    "float32",
    "float64",
    "bool",
)
NON_FINITE = {"inf": math.inf, "-inf": -math.inf}


def policy_files(path: str | Path) -> tuple[Path, Path] | None:
    """The (weights, policy.json) pair that `path` names (either file of it), or None where it names no such pair."""
    path = Path(path)
    if path.suffix not in (WEIGHTS, META):
        return None
    return path.with_suffix(WEIGHTS), path.with_suffix(META)


def is_policy_file(path: str | Path) -> bool:
    """Whether `path` is (either file of) a policy file pair in the safe format: a name, not a look inside."""
    return policy_files(path) is not None


# -- spaces as JSON --------------------------------------------------------------------------------------------------


def space_to_data(space: Any) -> dict[str, Any]:
    """A Gymnasium space as JSON data: Box, Discrete, MultiDiscrete, MultiBinary and Dicts of them."""
    from gymnasium import spaces

    if isinstance(space, spaces.Box):
        return {
            "type": "Box",
            "shape": list(space.shape),
            "dtype": str(space.dtype),
            "low": _bounds(space.low),
            "high": _bounds(space.high),
        }
    if isinstance(space, spaces.Discrete):
        return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}
    if isinstance(space, spaces.MultiDiscrete):
        return {"type": "MultiDiscrete", "nvec": space.nvec.tolist(), "start": space.start.tolist()}
    if isinstance(space, spaces.MultiBinary):
        return {"type": "MultiBinary", "n": np.asarray(space.n).tolist()}
    if isinstance(space, spaces.Dict):
        return {"type": "Dict", "spaces": {str(k): space_to_data(s) for k, s in space.spaces.items()}}
    raise PolicyFileError(
        f"a {type(space).__name__} space cannot be written in a policy file (Box, Discrete, MultiDiscrete, MultiBinary, Dict)"
    )


def _bounds(values: np.ndarray) -> Any:
    """A Box's bounds: one number where all are equal, else nested lists; infinities as "inf" and "-inf"."""

    def number(x: float) -> Any:
        return x if math.isfinite(x) else ("inf" if x > 0 else "-inf")

    flat = values.reshape(-1)
    if flat.size and np.all(flat == flat[0]):
        return number(flat[0].item())
    return np.vectorize(number, otypes=[object])(values).tolist() if values.size else []


def space_from_data(data: Any, what: str = "space") -> Any:
    """The Gymnasium space :func:`space_to_data` wrote; anything else is a PolicyFileError naming `what`."""
    from gymnasium import spaces

    if not isinstance(data, dict):
        raise PolicyFileError(f"{what}: expected a mapping with 'type', got {data!r}")
    kind = data.get("type")
    try:
        if kind == "Box":
            dtype = data["dtype"]
            if dtype not in SPACE_DTYPES:
                raise PolicyFileError(f"{what}.dtype: {dtype!r} is not one of {', '.join(SPACE_DTYPES)}")
            shape = tuple(int(n) for n in data["shape"])
            low, high = (np.asarray(_numbers(data[k])) for k in ("low", "high"))
            return spaces.Box(
                low.astype(dtype) if low.ndim else low.item(),
                high.astype(dtype) if high.ndim else high.item(),
                shape,
                np.dtype(dtype).type,
            )
        if kind == "Discrete":
            return spaces.Discrete(int(data["n"]), start=int(data.get("start", 0)))
        if kind == "MultiDiscrete":
            return spaces.MultiDiscrete(
                np.asarray(data["nvec"], dtype=np.int64), start=np.asarray(data.get("start", 0), dtype=np.int64)
            )
        if kind == "MultiBinary":
            return spaces.MultiBinary(data["n"])
        if kind == "Dict":
            return spaces.Dict({str(k): space_from_data(v, f"{what}.{k}") for k, v in data["spaces"].items()})
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise PolicyFileError(
            f"{what}: not a {kind} space as visualenv writes one ({type(exc).__name__}: {exc})"
        ) from None
    raise PolicyFileError(f"{what}.type: {kind!r} is not one of Box, Discrete, MultiDiscrete, MultiBinary, Dict")


def _numbers(value: Any) -> Any:
    if isinstance(value, list):
        return [_numbers(v) for v in value]
    if isinstance(value, str) and value in NON_FINITE:
        return NON_FINITE[value]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return value
    raise PolicyFileError(f'a space\'s bound is {value!r}: expected a number, "inf" or "-inf"')


# -- weights ---------------------------------------------------------------------------------------------------------


def weights_of(module: Any, half: bool) -> dict[str, Any]:
    """The module's state dict to save: a tensor that several names share (SB3's actor-critic lists its shared features
    extractor under three) once, under its first name; contiguous; its floats in float16 where `half`."""
    seen: set[tuple[int, tuple[int, ...]]] = set()
    weights = {}
    for name, value in module.state_dict().items():
        tensor = value.detach().cpu()
        shared = (tensor.data_ptr(), tuple(tensor.shape))
        if tensor.numel() and shared in seen:
            continue
        seen.add(shared)
        weights[name] = (tensor.half() if half and tensor.is_floating_point() else tensor).contiguous().clone()
    return weights


def read_weights_into(module: Any, path: Path) -> None:
    """The file's tensors into `module` (floats cast to the module's dtype); a missing or extra name is an error."""
    from safetensors import SafetensorError
    from safetensors.torch import load_model

    try:
        load_model(module, path, strict=True)
    except (SafetensorError, RuntimeError, OSError) as exc:
        detail = " ".join(str(exc).split())[:400]
        raise PolicyFileError(
            f"{path}: its weights do not fit the network its policy.json describes: {detail}"
        ) from None


# -- writing and reading ---------------------------------------------------------------------------------------------


def write_policy(
    out: str | Path,
    module: Any,
    *,
    backend: str,
    algorithm: str | None,
    half: bool,
    frame_stack: int | None = None,
    spec: dict[str, Any] | None = None,
) -> tuple[Path, Path]:
    """Write `module` (an SB3 policy or an RLlib RLModule) as OUT.safetensors and OUT.json; the two paths."""
    from safetensors.torch import save_file

    from visualenv.train.reproducible import machine_record

    pair = policy_files(out)
    if pair is None:
        raise PolicyFileError(f"{out}: a policy file's name ends in {WEIGHTS} (its {META} is written beside it)")
    weights_path, meta_path = pair
    kind, arguments = sb3_kind(module) if backend == "sb3" else rllib_kind(module)
    machine = {k: v for k, v in machine_record(False).items() if k != "pinned"}
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "backend": backend,
        "algorithm": algorithm,
        "policy": kind,
        "arguments": arguments,
        "observation_space": space_to_data(module.observation_space),
        "action_space": space_to_data(module.action_space),
        "frame_stack": frame_stack,
        "spec": spec,
        "weights": weights_path.name,
        "dtype": "float16" if half else "float32",
        "machine": machine,
    }
    text = json.dumps(meta, indent=2, allow_nan=False) + "\n"  # strict JSON: a policy file's numbers are finite
    try:
        weights_path.parent.mkdir(parents=True, exist_ok=True)
        save_file(weights_of(module, half), str(weights_path), metadata={"format": FORMAT, "policy": meta_path.name})
        meta_path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise PolicyFileError(f"cannot write {weights_path}: {exc.strerror or exc}") from None
    return weights_path, meta_path


def read_meta(path: str | Path) -> dict[str, Any]:
    """policy.json of the pair `path` names, checked to be visualenv's format."""
    pair = policy_files(path)
    if pair is None:
        raise PolicyFileError(f"{path}: not a policy file (expected a name ending in {WEIGHTS} or {META})")
    weights_path, meta_path = pair
    missing = (
        f"{path}: a policy file is {weights_path.name} with {meta_path.name} beside it, and " + "{} does not exist"
    )
    if not meta_path.is_file():
        raise PolicyFileError(missing.format(meta_path))
    meta = check_format(
        read_json_as(meta_path, PolicyFileError), meta_path, "a policy file", FORMAT, FORMAT_VERSION, PolicyFileError
    )
    if not weights_path.is_file():
        raise PolicyFileError(missing.format(weights_path))
    return meta


def read_policy(path: str | Path) -> Any:
    """The policy that a policy file pair holds, in float32 on the CPU, ready to act: an SB3 policy, or an
    RLlib module behind SB3's ``predict`` (:class:`visualenv.train.rllib_setup.RLlibPolicy`).

    The network policy.json describes is checked against the weights' header, and the weights to be finite, before
    it is built (:mod:`visualenv.train.policy_check`)."""
    meta = read_meta(path)
    weights_path, meta_path = policy_files(path)  # type: ignore[misc]
    try:
        for what in ("observation_space", "action_space"):
            check_space_size(meta.get(what), what)
        observation_space = space_from_data(meta.get("observation_space"), "observation_space")
        action_space = space_from_data(meta.get("action_space"), "action_space")
    except PolicyFileError as exc:
        raise PolicyFileError(f"{meta_path}: {exc}") from None
    arguments = meta.get("arguments")
    if not isinstance(arguments, dict):
        raise PolicyFileError(f"{meta_path}: arguments: expected a mapping of the network's arguments")
    backend = meta.get("backend")
    if backend not in ("sb3", "rllib"):
        raise PolicyFileError(f"{meta_path}: backend {backend!r} is not sb3 or rllib")
    if backend == "sb3":

        def build() -> Any:
            return build_sb3_policy(meta.get("policy"), arguments, observation_space, action_space)

    else:
        build = _rllib_builder(meta, arguments, observation_space, action_space)
    check_against(_built(on_meta, build, meta, meta_path), weights_path, meta_path)
    check_finite(weights_path)
    module = _built(lambda make: make(), build, meta, meta_path)
    read_weights_into(module, weights_path)
    if backend == "sb3":
        module.set_training_mode(False)
        return module
    from visualenv.train.rllib_setup import RLlibPolicy

    module.eval()
    return RLlibPolicy(module)


def _built(how: Any, build: Any, meta: dict[str, Any], meta_path: Path) -> Any:
    """The network `build` makes, made `how` (on meta, or for real), its arguments checked first; what SB3 and RLlib
    raise for arguments that do not fit is a PolicyFileError that names policy.json."""
    try:
        check_arguments(meta.get("arguments"))
        return how(build)
    except PolicyFileError as exc:
        raise PolicyFileError(f"{meta_path}: {exc}") from None
    except (TypeError, ValueError, AssertionError, RuntimeError, IndexError, KeyError, ZeroDivisionError) as exc:
        detail = " ".join(f"{type(exc).__name__}: {exc}".split())[:400]
        raise PolicyFileError(f"{meta_path}: cannot build {meta.get('policy')} from its arguments: {detail}") from None


def _rllib_builder(meta: dict[str, Any], arguments: dict[str, Any], observation_space: Any, action_space: Any) -> Any:
    try:
        from visualenv.train.rllib_setup import quiet_deprecations
    except ImportError as exc:
        raise PolicyFileError(f"an RLlib policy needs Ray RLlib: pip install 'visualenv[ray]' ({exc})") from None

    def build() -> Any:
        with quiet_deprecations():
            return build_rllib_module(meta.get("policy"), arguments, observation_space, action_space)

    return build
