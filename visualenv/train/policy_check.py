"""A policy file checked against its weights before its network is built: nothing it asks for is allocated unchecked.

``policy.json`` says what network to build; ``policy.safetensors`` holds its weights.
A file from elsewhere could describe a network of gigabytes (``net_arch: [15000, 15000]``),
or hold weights that are integers, NaN or infinite. So, before the network is built:

* the lists among its arguments (the layers) are at most :data:`MAX_LIST` long;
* the network is built on torch's ``meta`` device, which gives every tensor's name, shape and
  dtype without memory or time, and it must have at most :data:`MAX_PARAMETERS` parameters
  (``VISUALENV_MAX_POLICY_PARAMETERS`` raises it);
* the safetensors header (its JSON, read without the tensors) must list exactly those tensors
  (a shared one once), at those shapes, in a floating-point dtype;
* every weight must be finite.

Each refusal names the file and the tensor or field.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any, Callable

from visualenv.train.policy_kinds import PolicyFileError

#: the parameters a policy file's network may have: 100 million, 400 MB in float32 (the shipped agents have < 3 million)
MAX_PARAMETERS = 100_000_000
#: the environment variable that raises (or lowers) :data:`MAX_PARAMETERS`
PARAMETERS_VARIABLE = "VISUALENV_MAX_POLICY_PARAMETERS"
#: the entries a list among the network's arguments may have (``net_arch``, ``conv_filters``: one per layer)
MAX_LIST = 256
#: the numbers a policy's observation (or action) may have, all its parts together: 2**24, a 4096 x 4096 image
MAX_SPACE_ELEMENTS = 2**24
#: safetensors' floating-point dtypes: what a policy's weights are stored as
FLOAT_DTYPES = ("F16", "BF16", "F32", "F64")


def max_parameters() -> int:
    """:data:`MAX_PARAMETERS`, or the count ``VISUALENV_MAX_POLICY_PARAMETERS`` gives."""
    given = os.environ.get(PARAMETERS_VARIABLE, "").strip().replace("_", "")
    if not given:
        return MAX_PARAMETERS
    if not given.isdigit():
        raise PolicyFileError(f"{PARAMETERS_VARIABLE}={given!r}: expected a count of parameters, such as 200000000")
    return int(given)


def check_arguments(arguments: Any, where: str = "arguments") -> None:
    """No list among the network's arguments longer than :data:`MAX_LIST` (each entry a layer that costs time to build)."""
    if isinstance(arguments, dict):
        for key, value in arguments.items():
            check_arguments(value, f"{where}.{key}")
    elif isinstance(arguments, list):
        if len(arguments) > MAX_LIST:
            raise PolicyFileError(
                f"{where}: {len(arguments)} entries; a policy file's network takes at most {MAX_LIST} (one per layer)"
            )
        for i, value in enumerate(arguments):
            check_arguments(value, f"{where}[{i}]")


def check_space_size(data: Any, what: str) -> None:
    """A space as policy.json gives it has at most :data:`MAX_SPACE_ELEMENTS` numbers, counted from its shapes before
    Gymnasium allocates its bounds (a malformed space is left to :func:`~visualenv.train.policy_format.space_from_data`)."""
    count = _elements(data)
    if count > MAX_SPACE_ELEMENTS:
        raise PolicyFileError(
            f"{what}: {count:,} numbers per step; a policy file's spaces have at most {MAX_SPACE_ELEMENTS:,}"
        )


def _elements(data: Any, depth: int = 0) -> int:
    if not isinstance(data, dict) or depth > 32:
        return 0
    kind = data.get("type")
    if kind == "Dict" and isinstance(data.get("spaces"), dict):
        return sum(_elements(s, depth + 1) for s in data["spaces"].values())
    if kind == "MultiDiscrete":
        return _count(data.get("nvec"))
    size: Any = data.get("shape") if kind == "Box" else data.get("n") if kind == "MultiBinary" else []
    if isinstance(size, list) and all(_whole(n) for n in size):
        return _numel(tuple(size))
    return int(size) if _whole(size) else 0


def _count(value: Any) -> int:
    return sum(_count(v) for v in value) if isinstance(value, list) else 1


def _whole(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def on_meta(build: Callable[[], Any]) -> Any:
    """What `build` returns, its tensors made on torch's ``meta`` device: shapes and dtypes, no memory, no time."""
    import torch

    with warnings.catch_warnings(), torch.device("meta"), _keep_on_meta():
        warnings.simplefilter("ignore")  # torch warns of zero-element tensors that are not initialised
        return build()


def _keep_on_meta() -> Any:
    from torch.overrides import TorchFunctionMode

    class KeepOnMeta(TorchFunctionMode):
        """``tensor.to(device)`` of a meta tensor stays on meta (SB3 moves the layers it builds to its device)."""

        def __torch_function__(self, func: Any, types: Any, args: Any = (), kwargs: Any = None) -> Any:
            import torch

            kwargs = kwargs or {}
            if func is torch.Tensor.to and args and isinstance(args[0], torch.Tensor) and args[0].is_meta:
                dtype = kwargs.get("dtype") or next((a for a in args[1:] if isinstance(a, torch.dtype)), None)
                return args[0] if dtype is None else func(args[0], dtype)
            return func(*args, **kwargs)

    return KeepOnMeta()


def read_header(path: Path) -> dict[str, tuple[str, tuple[int, ...]]]:
    """Each tensor's (dtype, shape) from a safetensors file's header, without reading the tensors."""
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), "pt") as f:
            slices = {name: f.get_slice(name) for name in f.keys()}
            return {name: (s.get_dtype(), tuple(s.get_shape())) for name, s in slices.items()}
    except (SafetensorError, OSError, ValueError) as exc:
        raise PolicyFileError(f"{path}: not a safetensors file ({' '.join(str(exc).split())[:200]})") from None


def check_against(network: Any, weights_path: Path, meta_path: Path) -> None:
    """The weights file's header lists exactly the tensors of `network` (built on meta from `meta_path`), at their
    shapes, in floating point; and the network is within :data:`MAX_PARAMETERS`."""
    expected = network.state_dict(keep_vars=True)
    groups: dict[int, list[str]] = {}  # a tensor several names share (a shared features extractor) is stored once
    for name, tensor in expected.items():
        groups.setdefault(id(tensor), []).append(name)
    found = read_header(weights_path)
    described = sum(expected[names[0]].numel() for names in groups.values())
    held = sum(_numel(shape) for _, shape in found.values())
    problems = []
    for name in found:
        if name not in expected:
            problems.append(f"tensor {name!r} is not one of the network's")
    for names in groups.values():
        present = [n for n in names if n in found]
        want = expected[names[0]]
        if not present:
            problems.append(f"tensor {names[0]!r} ({_shown(want.shape)}) is missing")
            continue
        if len(present) > 1:
            problems.append(f"tensors {', '.join(present)} are one shared tensor, stored {len(present)} times")
        dtype, shape = found[present[0]]
        if shape != tuple(want.shape):
            problems.append(
                f"tensor {present[0]!r} is {_shown(shape)} in the file and {_shown(want.shape)} in the network"
            )
    if problems:
        raise PolicyFileError(
            f"{weights_path} does not hold the network {meta_path.name} describes ({described:,} parameters; "
            f"the file holds {held:,}): {'; '.join(problems[:3])}"
            + (f" (and {len(problems) - 3} more)" if len(problems) > 3 else "")
        )
    for names in groups.values():
        name = next(n for n in names if n in found)
        dtype, want = found[name][0], expected[names[0]]
        if want.is_floating_point() and dtype not in FLOAT_DTYPES:
            raise PolicyFileError(
                f"{weights_path}: tensor {name!r} is {dtype}: a policy's weights are floating point ({', '.join(FLOAT_DTYPES)})"
            )
    limit = max_parameters()
    if described > limit:
        raise PolicyFileError(
            f"{meta_path}: describes a network of {described:,} parameters, above the {limit:,} a policy file may have "
            f"(set {PARAMETERS_VARIABLE} to raise it; docs/security.md)"
        )


def check_finite(weights_path: Path) -> None:
    """Every weight in the file is a finite number (NaN or infinity would be acted on, or fail mid-episode)."""
    import torch
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(weights_path), "pt") as f:
            for name in f.keys():
                tensor = f.get_tensor(name)
                if tensor.is_floating_point():
                    bad = int((~torch.isfinite(tensor)).sum())
                    if bad:
                        raise PolicyFileError(
                            f"{weights_path}: tensor {name!r} holds {bad} NaN or infinite values (of {tensor.numel()}): "
                            "a policy's weights are finite"
                        )
    except (SafetensorError, OSError) as exc:
        raise PolicyFileError(f"{weights_path}: cannot read its weights ({' '.join(str(exc).split())[:200]})") from None


def check_finite_module(module: Any, where: str) -> None:
    """Every floating-point tensor of `module` is finite: a policy file is not written with NaN or infinite weights."""
    import torch

    for name, tensor in module.state_dict().items():
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            bad = int((~torch.isfinite(tensor)).sum())
            raise PolicyFileError(
                f"{where}: tensor {name!r} holds {bad} NaN or infinite values (of {tensor.numel()}): "
                "a policy's weights are finite"
            )


def _numel(shape: tuple[int, ...]) -> int:
    count = 1
    for n in shape:
        count *= n
    return count


def _shown(shape: Any) -> str:
    return "[" + ", ".join(str(n) for n in shape) + "]"
