"""What a policy file may name: the fixed lists of SB3 and RLlib classes a ``policy.json`` chooses from.

A policy file is data (:mod:`visualenv.train.policy_format`). The network it holds is
built by a class, and a class named by a file would let the file choose the code that
runs; so ``policy.json`` names its policy kind, activation function, features extractor
and RLlib catalog by keys of the tables below, and visualenv builds the network with the
class its own table gives for that key. A name not in a table is an error that lists the
names it takes. Every other network argument is plain JSON (numbers, lists, strings, true/false).
"""

from __future__ import annotations

import inspect
from typing import Any, Callable

from visualenv.compat.sb3 import constructor_parameters
from visualenv.errors import ConfigError, VisualEnvError

#: SB3 constructor arguments a policy file leaves out: the spaces have their own keys, and the optimizer (its class,
#: settings and learning rate) only trains, which a policy file does not do
NOT_ARGUMENTS = ("self", "observation_space", "action_space", "lr_schedule", "optimizer_class", "optimizer_kwargs")
#: RLlib's activation names (``DefaultModelConfig``'s ``*_activation``) and torch's in-place initializers (``*_initializer``)
RLLIB_ACTIVATIONS = (None, "linear", "relu", "tanh", "elu", "swish", "silu")
RLLIB_INITIALIZERS = (
    None,
    "orthogonal_",
    "xavier_uniform_",
    "xavier_normal_",
    "kaiming_uniform_",
    "kaiming_normal_",
    "zeros_",
    "ones_",
    "normal_",
    "uniform_",
    "constant_",
    "trunc_normal_",
)


class PolicyFileError(VisualEnvError):
    """A policy file that is not what visualenv writes or can build."""


def dotted(cls: type) -> str:
    """A class's public dotted name, the key it has in the tables."""
    return f"{cls.__module__}.{cls.__qualname__}"


def sb3_policies() -> dict[str, type]:
    """The SB3 policy kinds of the algorithms `visualenv train` runs (PPO and A2C, DQN, SAC, DrQ's SAC)."""
    from stable_baselines3.common import policies
    from stable_baselines3.dqn import policies as dqn
    from stable_baselines3.sac import policies as sac

    from visualenv.train.drq import DrQSACPolicy

    kinds = (
        policies.ActorCriticPolicy,
        policies.ActorCriticCnnPolicy,
        policies.MultiInputActorCriticPolicy,
        dqn.DQNPolicy,
        dqn.CnnPolicy,
        dqn.MultiInputPolicy,
        sac.SACPolicy,
        sac.CnnPolicy,
        sac.MultiInputPolicy,
        DrQSACPolicy,  # `train --algo sac --augment shift`
    )
    return {dotted(cls): cls for cls in kinds}


def activations() -> dict[str, type]:
    """torch's activation modules, by the names ``torch.nn.<Name>``."""
    from torch import nn

    return {
        f"torch.nn.{cls.__name__}": cls
        for cls in (
            nn.Tanh,
            nn.ReLU,
            nn.LeakyReLU,
            nn.ELU,
            nn.SELU,
            nn.GELU,
            nn.SiLU,
            nn.Mish,
            nn.Sigmoid,
            nn.Softplus,
            nn.Identity,
        )
    }


def features_extractors() -> dict[str, type]:
    """SB3's own features extractors and visualenv's (:mod:`visualenv.train.encoders`); any other is code: export
    refuses it."""
    from stable_baselines3.common import torch_layers

    from visualenv.train.encoders import DrQEncoder

    kinds = (torch_layers.NatureCNN, torch_layers.FlattenExtractor, torch_layers.CombinedExtractor, DrQEncoder)
    return {dotted(cls): cls for cls in kinds}


#: SB3 arguments that are classes, and the table each is named from
CLASS_ARGUMENTS: dict[str, Callable[[], dict[str, type]]] = {
    "activation_fn": activations,
    "features_extractor_class": features_extractors,
}


def named_classes(policy_kwargs: Any) -> Any:
    """A training config's ``policy_kwargs`` with the classes it names by keys of the tables above
    (``features_extractor_class: visualenv.train.encoders.DrQEncoder``) looked up, as a policy file's are."""
    if not isinstance(policy_kwargs, dict):
        return policy_kwargs
    try:
        return {
            key: chosen(CLASS_ARGUMENTS[key](), value, f"policy_kwargs.{key}")
            if key in CLASS_ARGUMENTS and isinstance(value, str)
            else value
            for key, value in policy_kwargs.items()
        }
    except PolicyFileError as exc:
        raise ConfigError(str(exc)) from None


def rllib_modules() -> dict[str, type]:
    """The RLModule kinds `visualenv train --backend rllib` trains (PPO's default torch module)."""
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule

    return {dotted(DefaultPPOTorchRLModule): DefaultPPOTorchRLModule}


def rllib_catalogs() -> dict[str, type]:
    from ray.rllib.algorithms.ppo.ppo_catalog import PPOCatalog

    return {dotted(PPOCatalog): PPOCatalog}


def chosen(table: dict[str, type], name: Any, what: str) -> type:
    """The class `table` holds under `name`; any other name is an error listing the allowed ones."""
    if isinstance(name, str) and name in table:
        return table[name]
    raise PolicyFileError(f"{what} {name!r} is not one visualenv builds; allowed: {', '.join(table)}")


def name_of(table: dict[str, type], cls: Any, what: str) -> str:
    """The key of `cls` in `table`: what a policy file writes for it."""
    for name, known in table.items():
        if cls is known:
            return name
    shown = dotted(cls) if isinstance(cls, type) else repr(cls)
    raise PolicyFileError(f"{what} {shown} cannot be written as data: a policy file names one of {', '.join(table)}")


def as_data(value: Any, what: str) -> Any:
    """`value` as JSON data (tuples as lists, numpy numbers as numbers); anything else is an error naming `what`."""
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        if value != value or value in (float("inf"), float("-inf")):
            raise PolicyFileError(f"{what} is {value}: a policy file holds finite numbers only")
        return value
    if hasattr(value, "item") and getattr(value, "shape", None) == ():  # a numpy scalar
        return as_data(value.item(), what)
    if isinstance(value, (list, tuple)):
        return [as_data(v, what) for v in value]
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return {k: as_data(v, f"{what}.{k}") for k, v in value.items()}
    raise PolicyFileError(f"{what} is a {type(value).__name__}, which a policy file cannot hold as data")


# -- SB3 ------------------------------------------------------------------------------------------------------------


def sb3_kind(policy: Any) -> tuple[str, dict[str, Any]]:
    """The policy's kind and its network arguments as data, for policy.json."""
    name = name_of(sb3_policies(), type(policy), "the policy class")
    parameters = constructor_parameters(policy)  # SB3's own record of what rebuilds the policy
    if "share_features_extractor" in inspect.signature(type(policy)).parameters:
        parameters["share_features_extractor"] = policy.share_features_extractor  # SB3's record leaves it out
    arguments: dict[str, Any] = {}
    for key, value in parameters.items():
        if key in NOT_ARGUMENTS:
            continue
        if key in CLASS_ARGUMENTS:
            arguments[key] = name_of(CLASS_ARGUMENTS[key](), value, key)
        else:
            arguments[key] = as_data(value, key)
    return name, arguments


def build_sb3_policy(kind: Any, arguments: dict[str, Any], observation_space: Any, action_space: Any) -> Any:
    """A fresh SB3 policy of an allowed `kind`, with the arguments policy.json gives (classes looked up by name)."""
    cls = chosen(sb3_policies(), kind, "policy")
    known = [n for n in inspect.signature(cls).parameters if n not in NOT_ARGUMENTS]
    unknown = sorted(set(arguments) - set(known))
    if unknown:
        raise PolicyFileError(f"{', '.join(unknown)}: not arguments of {kind}; it takes {', '.join(known)}")
    kwargs = {k: chosen(CLASS_ARGUMENTS[k](), v, k) if k in CLASS_ARGUMENTS else v for k, v in arguments.items()}
    return cls(observation_space=observation_space, action_space=action_space, lr_schedule=_no_learning, **kwargs)


def _no_learning(progress: float) -> float:
    """The learning rate of a policy that only acts (SB3 builds an optimizer with it, which never steps)."""
    return 0.0


# -- RLlib ------------------------------------------------------------------------------------------------------------


def rllib_kind(module: Any) -> tuple[str, dict[str, Any]]:
    """The RLModule's kind and its constructor arguments as data, for policy.json."""
    name = name_of(rllib_modules(), type(module), "the RLModule class")
    _, kwargs = module.get_ctor_args_and_kwargs()
    config = kwargs["model_config"]
    if not isinstance(config, dict):  # a DefaultModelConfig dataclass
        import dataclasses

        config = dataclasses.asdict(config)
    arguments = {
        "inference_only": bool(kwargs["inference_only"]),
        "learner_only": bool(kwargs["learner_only"]),
        "model_config": as_data(config, "model_config"),
        "catalog_class": name_of(rllib_catalogs(), kwargs["catalog_class"], "catalog_class"),
    }
    check_model_config(arguments["model_config"])
    return name, arguments


def check_model_config(config: Any) -> None:
    """RLlib's model config as plain settings: its own keys, activations and initializers from the allowed names."""
    import dataclasses

    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    if not isinstance(config, dict):
        raise PolicyFileError(
            f"model_config: expected a mapping of RLlib's model settings, got {type(config).__name__}"
        )
    known = [f.name for f in dataclasses.fields(DefaultModelConfig)]
    for key, value in config.items():
        if key not in known:
            raise PolicyFileError(f"model_config.{key}: not a setting of RLlib's DefaultModelConfig")
        if key.endswith("_activation") and value not in RLLIB_ACTIVATIONS:
            raise PolicyFileError(
                f"model_config.{key}: {value!r} is not one of {', '.join(map(str, RLLIB_ACTIVATIONS))}"
            )
        if key.endswith("_initializer") and value not in RLLIB_INITIALIZERS:
            raise PolicyFileError(
                f"model_config.{key}: {value!r} is not one of {', '.join(map(str, RLLIB_INITIALIZERS))}"
            )


def build_rllib_module(kind: Any, arguments: dict[str, Any], observation_space: Any, action_space: Any) -> Any:
    """A fresh RLModule of an allowed `kind` with the arguments policy.json gives."""
    cls = chosen(rllib_modules(), kind, "policy")
    expected = {"inference_only", "learner_only", "model_config", "catalog_class"}
    if set(arguments) != expected:
        raise PolicyFileError(
            f"arguments: an RLModule takes exactly {', '.join(sorted(expected))}, got {', '.join(sorted(arguments))}"
        )
    check_model_config(arguments["model_config"])
    catalog = chosen(rllib_catalogs(), arguments["catalog_class"], "catalog_class")
    return cls(
        observation_space=observation_space,
        action_space=action_space,
        inference_only=bool(arguments["inference_only"]),
        learner_only=bool(arguments["learner_only"]),
        model_config=dict(arguments["model_config"]),
        catalog_class=catalog,
    )
