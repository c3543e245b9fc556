"""Trained models: load a policy file, or (trusted) an SB3 model or RLlib checkpoint; save a policy file; fit an env to a model.

Every kind loads into an object with SB3's ``predict``, ``observation_space`` and
``action_space``, which is all that ``play`` and the evaluations use.

A *policy file* is data: ``policy.safetensors`` (the weights) with ``policy.json``
(what builds the network), read without unpickling anything
(:mod:`visualenv.train.policy_format`). It is what `visualenv export-policy` and
`visualenv train` write and what the shipped agents are.

SB3's ``.zip``, a torch ``.pt``/``.pth`` and an RLlib checkpoint folder are
pickle-based: unpickling runs whatever code the file holds. They load only with
``trust_pickle=True`` (``--trust-pickle``); without it, loading one is an error that
says how to convert it once (docs/security.md).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from visualenv.env.wrappers import FrameStack, subspaces
from visualenv.errors import VisualEnvError
from visualenv.train.policy_format import WEIGHTS, is_policy_file, read_meta, read_policy, write_policy
from visualenv.spec.loader import spec_identity
from visualenv.train.run_folder import SHIPPED_POLICY, RunFolder, RunFolderError, read_config

#: the shipped agents live in the source checkout: results/<Id>/policy.safetensors with its policy.json
RESULTS_DIR = Path(__file__).resolve().parents[2] / "results"


class PickleRefused(VisualEnvError):
    """A pickle-based model file, loaded without trust_pickle: loading it could run code."""


def algorithm_class(name: str, augment: str | None = None) -> Any:
    """The SB3 algorithm `train` and `play` name (``ppo``, ``a2c``, ``dqn``, ``sac``); with `augment`, SAC is DrQ's
    (:class:`~visualenv.train.drq.DrQSAC`: DrQ's update schedule)."""
    import stable_baselines3 as sb3

    classes = {"ppo": sb3.PPO, "a2c": sb3.A2C, "dqn": sb3.DQN, "sac": sb3.SAC}
    if name not in classes:
        raise ValueError(f"unknown algorithm '{name}': expected one of {', '.join(classes)}")
    if name == "sac" and augment is not None:
        from visualenv.train.drq import DrQSAC

        return DrQSAC
    return classes[name]


def load_model(model_path: str | Path, algo: str = "ppo", *, trust_pickle: bool = False) -> Any:
    """A policy file (policy.safetensors + policy.json); with `trust_pickle`, also an SB3 model (.zip), a torch policy
    file (.pt, .pth) or the policy of an RLlib checkpoint folder (`train --backend rllib`), whose unpickling runs any
    code they hold."""
    path = Path(model_path)
    if is_policy_file(path):
        return read_policy(path)
    if not trust_pickle:
        raise PickleRefused(pickle_refusal(path))
    if path.is_dir():
        return _load_rllib(path)
    if path.suffix in (".pt", ".pth"):
        return _load_torch_policy(path)
    try:
        return algorithm_class(algo).load(path, device="cpu")
    except Exception as exc:  # SB3 raises whatever its unpickling met: report it, whatever it is
        raise VisualEnvError(f"cannot load {path} as a {algo.upper()} model: {exc}") from None


def load_policy_file(model_path: str | Path, command: str) -> Any:
    """A policy file, for `command`, which takes no pickle-based model (it has no --trust-pickle): any other file is
    refused with the way to convert it once."""
    path = Path(model_path)
    if not is_policy_file(path):
        raise PickleRefused(pickle_refusal(path, command=command))
    return read_policy(path)


def pickle_refusal(path: Path, command: str | None = None) -> str:
    """Why a file that is not a policy file is not loaded, and what to do about it; for a `command` that takes policy
    files only, the conversion alone."""
    kind = (
        "an RLlib checkpoint folder: a pickle-based file"
        if path.is_dir()
        else f"a torch {path.suffix} file: a pickle-based file"
        if path.suffix in (".pt", ".pth")
        else "an SB3 model: a pickle-based file"
        if path.suffix == ".zip"
        else f"not a policy file ({WEIGHTS} with its .json), so it would load as a pickle-based file"
    )
    convert = f"`visualenv export-policy --trust-pickle {path} OUT{WEIGHTS}`, then use OUT{WEIGHTS} (docs/security.md)"
    if command is not None:
        return (
            f"{path} is {kind}, and loading it can run any code it holds; `visualenv {command}` takes policy files "
            f"only. If you trust where it came from, convert it once: {convert}"
        )
    return (
        f"{path} is {kind}, and loading it can run any code it holds. If you trust where it came from, "
        f"pass --trust-pickle (Python: trust_pickle=True), or convert it once: {convert}"
    )


def _load_rllib(path: Path) -> Any:
    try:
        from visualenv.train.rllib_setup import RLlibPolicy, is_checkpoint
    except ImportError as exc:
        raise VisualEnvError(
            f"{path} is a folder: an RLlib checkpoint needs Ray RLlib (pip install 'visualenv[ray]'; {exc})"
        ) from None
    if not is_checkpoint(path):
        raise VisualEnvError(
            f"{path} is not a checkpoint of `visualenv train --backend rllib` (no {Path('learner_group', 'learner', 'rl_module')})"
        )
    try:
        return RLlibPolicy.load(path)
    except Exception as exc:  # RLlib raises whatever its unpickling met
        raise VisualEnvError(f"cannot load {path} as an RLlib checkpoint: {exc}") from None


def _load_torch_policy(path: Path) -> Any:
    """A policy saved by SB3's ``BasePolicy.save`` (or an earlier visualenv's export): a pickle, trusted by the caller."""
    import torch

    from visualenv.train.policy_kinds import sb3_policies

    try:
        saved = torch.load(path, map_location="cpu", weights_only=False)
        kind = saved.get("policy_class", "").replace(":", ".") if isinstance(saved, dict) else ""
        policy = sb3_policies()[kind](**saved["data"]) if kind in sb3_policies() else None
        if policy is None:
            raise ValueError(
                f"it names no SB3 policy class visualenv knows ({kind or 'none'}): load it with its class's load()"
            )
        policy.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in saved["state_dict"].items()})
    except Exception as exc:  # a file of another kind: say so, whatever torch or SB3 raised
        raise VisualEnvError(f"cannot load {path} as a policy file: {type(exc).__name__}: {exc}") from None
    policy.set_training_mode(False)
    return policy


def save_policy(
    model: Any, out: str | Path, *, half: bool = True, algorithm: str | None = None, run_dir: Path | None = None
) -> Path:
    """The policy of an SB3 model (or an SB3 policy) as a policy file OUT.safetensors + OUT.json (`half`: float16 weights).

    `run_dir`: the run folder whose config.json names the algorithm, the env and the frame stack."""
    policy = model.policy if hasattr(model, "policy") else model
    record = run_record(run_dir)
    record["algorithm"] = algorithm or _algorithm_name(model) or record["algorithm"]
    weights, _ = write_policy(out, policy, backend="sb3", half=half, **record)
    return weights


def save_rllib_module(module: Any, out: str | Path, *, half: bool = True, run_dir: Path | None = None) -> Path:
    """An RLlib RLModule (an RLlibPolicy's, or a training algorithm's) as a policy file OUT.safetensors + OUT.json."""
    module = getattr(module, "module", module)
    weights, _ = write_policy(out, module, backend="rllib", half=half, **{**run_record(run_dir), "algorithm": "ppo"})
    return weights


def export_policy(
    model_path: str | Path,
    out: str | Path,
    *,
    algo: str = "ppo",
    half: bool = True,
    trust_pickle: bool = False,
    force: bool = False,
) -> Path:
    """`visualenv export-policy`: any model :func:`load_model` takes, as a policy file, with what the run beside it
    records (its config.json); a policy file exported again keeps what it knew. An existing OUT pair is replaced only
    with `force`; weights that are not finite are refused."""
    from visualenv.train.policy_check import check_finite_module
    from visualenv.train.policy_format import policy_files

    source = Path(model_path)
    pair = policy_files(out)
    existing = [p for p in pair or () if p.exists()]
    if existing and not force:
        raise VisualEnvError(
            f"{' and '.join(map(str, existing))} already exist{'s' if len(existing) == 1 else ''}: "
            "pass --force (Python: force=True) to replace them"
        )
    model = load_model(source, algo, trust_pickle=trust_pickle)
    module = model.module if hasattr(model, "module") else getattr(model, "policy", model)
    check_finite_module(module, str(source))
    if hasattr(model, "module"):  # an RLlib policy
        weights = save_rllib_module(model, out, half=half, run_dir=source.parent)
    else:
        weights = save_policy(
            model, out, half=half, algorithm=algo if source.suffix == ".zip" else None, run_dir=source.parent
        )
    if is_policy_file(source):
        carried, meta_path = read_meta(source), weights.with_suffix(".json")
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        meta.update({k: carried.get(k) for k in ("algorithm", "frame_stack", "spec") if meta.get(k) is None})
        meta_path.write_text(json.dumps(meta, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return weights


def _algorithm_name(model: Any) -> str | None:
    name = type(model).__name__.lower()
    return name if name in ("ppo", "a2c", "dqn", "sac") else None


def run_record(run_dir: Path | None) -> dict[str, Any]:
    """What a run folder's config.json says of a policy it trained: the algorithm, the frame stack, the spec's id and
    the sha256 of its spec file (as `visualenv build` records it); None for what it does not say."""
    from visualenv.env.registration import resolve

    record: dict[str, Any] = {"algorithm": None, "frame_stack": None, "spec": None}
    if run_dir is None or not RunFolder(run_dir).is_run():
        return record
    try:
        config = read_config(run_dir)["config"]
    except RunFolderError:
        return record  # a config.json that is not a run's (a model file kept beside another tool's): it says nothing
    record["algorithm"] = config["algo"]
    record["frame_stack"] = config["frame_stack"] if config["render"] else 0
    try:
        record["spec"] = spec_identity(resolve(str(config["spec"])))
    except (VisualEnvError, OSError):
        pass  # a spec that moved or no longer loads: the file says nothing of it rather than something wrong
    return record


#: ``--model``'s name for a bundled env's shipped agent; ``pretrained:NAME`` names another agent shipped beside it
PRETRAINED = "pretrained"


def is_pretrained(model: str) -> bool:
    """Whether ``--model`` names a shipped agent (``pretrained`` or ``pretrained:NAME``) rather than a file."""
    return model == PRETRAINED or model.startswith(PRETRAINED + ":")


def pretrained_model(env_id: str, model: str = PRETRAINED) -> Path:
    """The shipped agent of a bundled env: results/<Id>/policy.safetensors (with its policy.json) in the source checkout.

    ``pretrained:NAME`` is the agent in results/<Id>/NAME/ (the DMC cartpole's student trained on distracted frames is
    ``pretrained:robust``); an unknown name is an error listing the names there are.
    """
    folder = RESULTS_DIR / env_id
    name = model.partition(":")[2]
    if name:  # one of the folders beside the main agent that hold one: nothing else, so no path leads elsewhere
        there = sorted(p.parent.name for p in folder.glob(f"*/{SHIPPED_POLICY}"))
        if name not in there:
            names = ", ".join([PRETRAINED, *(f"{PRETRAINED}:{n}" for n in there)])
            listed = f"there are {names}" if there else f"there is only {PRETRAINED}"
            raise VisualEnvError(f"{model}: no such shipped agent of {env_id}; {listed}")
        folder = folder / name
    path = RunFolder(folder).shipped_policy
    if not path.is_file():
        raise VisualEnvError(
            f"no shipped model for {env_id}: {path} does not exist "
            "(the shipped models come with a checkout of the repository; train one with `visualenv train`)"
        )
    return path


def stacked_like(env: Any, model: Any, model_path: str) -> Any:
    """`env` with the frame stack the model was trained on; a model of another env is an error, not a crash mid-episode."""
    want, have = model.observation_space, env.observation_space
    depth = next((w // h for w, h in _channel_pairs(want, have) if w != h and w % h == 0), 1)
    if depth > 1:
        env = FrameStack(env, depth)
    actions, ours = model.action_space, env.action_space
    if (
        not _fits(want, env.observation_space)
        or type(actions) is not type(ours)
        or actions.shape != ours.shape
        or getattr(actions, "n", None) != getattr(ours, "n", None)
    ):
        raise VisualEnvError(
            f"{model_path} was trained on observations {_shapes(want)} and actions {actions}; "
            f"this env has observations {_shapes(env.observation_space)} and actions {ours}"
        )
    return env


def _channel_pairs(want: Any, have: Any) -> list[tuple[int, int]]:
    """(model's channels, env's channels) of each image both have: their ratio is the frame stack."""
    from stable_baselines3.common.preprocessing import is_image_space_channels_first

    ours = subspaces(have)
    pairs = []
    for key, w in subspaces(want).items():
        h = ours.get(key)
        if h is not None and len(w.shape or ()) == 3 and len(h.shape or ()) == 3:
            pairs.append((w.shape[0] if is_image_space_channels_first(w) else w.shape[-1], h.shape[-1]))  # type: ignore[arg-type,index]
    return pairs


def _fits(want: Any, have: Any) -> bool:
    """Same keys and shapes; SB3 also takes channel-last images for a channel-first model."""
    w, h = subspaces(want), subspaces(have)
    return w.keys() == h.keys() and all(
        w[k].shape is not None
        and h[k].shape is not None
        and w[k].shape in (h[k].shape, h[k].shape[-1:] + h[k].shape[:-1])  # type: ignore[index]
        for k in w
    )


def _shapes(space: Any) -> Any:
    by_key = subspaces(space)
    return by_key[""].shape if list(by_key) == [""] else {k: s.shape for k, s in by_key.items()}
