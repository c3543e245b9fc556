"""Trained models: load an SB3 model, a policy file or an RLlib checkpoint; save a policy; fit an env to a model.

Every kind loads into an object with SB3's ``predict``, ``observation_space`` and
``action_space``, which is all that ``play`` and the evaluations use.

A *policy file* (``.pt``) is an SB3 policy without its algorithm: the weights
(half precision by default, about a third of the size of the ``.zip``, which
also holds the optimizer's state) and the policy's constructor arguments, in the
format of SB3's own ``BasePolicy.save``, so SB3 loads it directly::

    from stable_baselines3.common.policies import ActorCriticCnnPolicy
    policy = ActorCriticCnnPolicy.load("results/Goalie-v0/policy.pt")   # policy.predict(obs, deterministic=True)
"""

from __future__ import annotations

import io
from importlib import import_module
from pathlib import Path
from typing import Any

from visualenv.env.wrappers import FrameStack, subspaces
from visualenv.errors import VisualEnvError

POLICY_SUFFIXES = (".pt", ".pth")
#: the shipped agents live in the source checkout: results/<Id>/policy.pt
RESULTS_DIR = Path(__file__).resolve().parents[2] / "results"


def algorithm_class(name: str) -> Any:
    """The SB3 algorithm `train` and `play` name (``ppo``, ``a2c``, ``dqn``, ``sac``)."""
    import stable_baselines3 as sb3

    classes = {"ppo": sb3.PPO, "a2c": sb3.A2C, "dqn": sb3.DQN, "sac": sb3.SAC}
    if name not in classes:
        raise ValueError(f"unknown algorithm '{name}': expected one of {', '.join(classes)}")
    return classes[name]


def load_model(model_path: str, algo: str = "ppo") -> Any:
    """An SB3 model (.zip), a policy file (.pt) or the policy of an RLlib checkpoint folder (`train --backend rllib`)."""
    if Path(model_path).is_dir():
        return _load_rllib(model_path)
    if Path(model_path).suffix in POLICY_SUFFIXES:
        return load_policy(model_path)
    try:
        return algorithm_class(algo).load(model_path, device="cpu")
    except Exception as exc:  # SB3 raises whatever its unpickling met: report it, whatever it is
        raise VisualEnvError(f"cannot load {model_path} as a {algo.upper()} model: {exc}") from None


def _load_rllib(model_path: str) -> Any:
    try:
        from visualenv.train.rllib_setup import RLlibPolicy, is_checkpoint
    except ImportError as exc:
        raise VisualEnvError(f"{model_path} is a folder: an RLlib checkpoint needs Ray RLlib (pip install 'visualenv[ray]'; {exc})") from None
    if not is_checkpoint(model_path):
        raise VisualEnvError(f"{model_path} is not a checkpoint of `visualenv train --backend rllib` (no {Path('learner_group', 'learner', 'rl_module')})")
    try:
        return RLlibPolicy.load(model_path)
    except Exception as exc:  # RLlib raises whatever its unpickling met
        raise VisualEnvError(f"cannot load {model_path} as an RLlib checkpoint: {exc}") from None


def save_policy(model: Any, path: str | Path, *, half: bool = True) -> Path:
    """The policy of an SB3 model as a policy file (SB3's ``BasePolicy.save`` format; `half`: float16 weights), its
    large weights packed (:mod:`visualenv.train.packed`: the same numbers in 8 % less space)."""
    import copy

    import torch

    from visualenv.train.packed import packed_state

    policy = model.policy if hasattr(model, "policy") else model
    # converted as a module, so the feature extractor that SB3 lists three times (shared by both heads) is stored once
    weights = packed_state((copy.deepcopy(policy).half() if half else policy).state_dict())
    kind = type(policy)
    path = Path(path)
    buffer = io.BytesIO()
    torch.save({"state_dict": weights, "data": policy._get_constructor_parameters(),
                "policy_class": f"{kind.__module__}:{kind.__qualname__}"}, buffer, pickle_protocol=4)  # bytes as they are
    deflate_zip(buffer.getvalue(), path)
    return path


def deflate_zip(archive: bytes, path: Path) -> None:
    """Write torch.save's zip archive to `path` with its entries deflated: the same tensors, which torch.load (and so
    SB3's ``BasePolicy.load``) reads as they are, in 11 % less space (a float16 policy: 5.68 -> 5.05 MB)."""
    import zipfile

    with zipfile.ZipFile(io.BytesIO(archive)) as source, zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=9) as out:
        for entry in source.infolist():
            out.writestr(entry.filename, source.read(entry))


def save_rllib_policy(checkpoint: str | Path, out: str | Path, *, half: bool = True) -> Path:
    """The policy of an RLlib checkpoint folder (its RLModule, without the learner's optimizer) as a checkpoint folder
    that :func:`load_model` and RLlib's ``RLModule.from_checkpoint`` read; `half`: float16 weights. Its pickles are
    written again with their large arrays packed (:mod:`visualenv.train.packed`), which RLlib unpickles as they were."""
    import pickle
    import shutil

    import numpy as np

    from visualenv.train import packed
    from visualenv.train.rllib_setup import MODULE_DIR

    source, target = Path(checkpoint) / MODULE_DIR, Path(out) / MODULE_DIR
    if not source.is_dir():
        raise VisualEnvError(f"{checkpoint} is not a checkpoint of `visualenv train --backend rllib` (no {MODULE_DIR})")
    shutil.copytree(source, target, dirs_exist_ok=True)
    steps = Path(checkpoint) / "visualenv.json"  # the steps the checkpoint had trained
    if steps.is_file():
        shutil.copy2(steps, Path(out) / steps.name)
    for name in ("module_state.pkl", "class_and_ctor_args.pkl"):
        if not (target / name).is_file():
            continue
        with (target / name).open("rb") as f:
            content = pickle.load(f)  # RLlib's own checkpoint files, which RLlib unpickles the same way
        if half and name == "module_state.pkl":
            content = type(content)((k, v.astype(np.float16) if getattr(v, "dtype", None) == np.float32 else v)
                                    for k, v in content.items())
        with (target / name).open("wb") as f:
            packed.dump(content, f)
    return Path(out)


def load_policy(path: str | Path) -> Any:
    """A policy file written by :func:`save_policy`, in float32 on the CPU."""
    import torch

    try:
        saved = torch.load(path, map_location="cpu", weights_only=False)
        module, _, name = saved["policy_class"].partition(":")
        policy = getattr(import_module(module), name)(**saved["data"])
        policy.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in saved["state_dict"].items()})
    except Exception as exc:  # a file of another kind: say so, whatever torch or SB3 raised
        raise VisualEnvError(f"cannot load {path} as a policy file of `visualenv export-policy`: {type(exc).__name__}: {exc}") from None
    policy.set_training_mode(False)
    return policy


def pretrained_model(env_id: str) -> Path:
    """The shipped agent of a bundled env: results/<Id>/policy.pt in the source checkout."""
    path = RESULTS_DIR / env_id / "policy.pt"
    if not path.is_file():
        raise VisualEnvError(f"no shipped model for {env_id}: {path} does not exist "
                             "(the shipped models come with a checkout of the repository; train one with `visualenv train`)")
    return path


def stacked_like(env: Any, model: Any, model_path: str) -> Any:
    """`env` with the frame stack the model was trained on; a model of another env is an error, not a crash mid-episode."""
    want, have = model.observation_space, env.observation_space
    depth = next((w // h for w, h in _channel_pairs(want, have) if w != h and w % h == 0), 1)
    if depth > 1:
        env = FrameStack(env, depth)
    actions, ours = model.action_space, env.action_space
    if not _fits(want, env.observation_space) or type(actions) is not type(ours) or actions.shape != ours.shape \
            or getattr(actions, "n", None) != getattr(ours, "n", None):
        raise VisualEnvError(f"{model_path} was trained on observations {_shapes(want)} and actions {actions}; "
                             f"this env has observations {_shapes(env.observation_space)} and actions {ours}")
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
        w[k].shape is not None and h[k].shape is not None and w[k].shape in (h[k].shape, h[k].shape[-1:] + h[k].shape[:-1]) for k in w)  # type: ignore[index]


def _shapes(space: Any) -> Any:
    by_key = subspaces(space)
    return by_key[""].shape if list(by_key) == [""] else {k: s.shape for k, s in by_key.items()}
