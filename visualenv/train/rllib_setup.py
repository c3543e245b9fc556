"""Ray RLlib backend: visualenv specs as RLlib envs, trained with PPO on a Ray cluster.

Install the ``[ray]`` extra. RLlib's new API stack builds the envs inside each
EnvRunner (a Ray actor, on any node) with ``gym.make_vec``; :func:`make_rllib_env`
is the creator it calls there, so every runner process builds its own Blender
renderer, at its envs' first reset. The local EnvRunner of the driver only holds
a copy of the model when there are remote runners: it makes no env, so it never
starts Blender (:func:`ppo_config` refuses zero remote runners for that reason).

The model sees what the SB3 backend's CnnPolicy sees: the last ``frame_stack``
frames stacked on the channel axis (:class:`~visualenv.env.wrappers.FrameStack`, in the
runner), scaled to [0, 1] (:class:`ScaledImage`: RLlib's CNN encoder convolves
its input as it comes). RLlib has default conv filters only for 42x42, 64x64 and
84x84 images; :func:`conv_filters` sizes them from the spec's observation.

This module imports ray; ``import visualenv`` never imports it.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from ray.rllib.callbacks.callbacks import RLlibCallback

from visualenv.compat.glibc import apply_policy
from visualenv.compat.ray import DEPRECATION_LOGGER, local_cluster_addresses
from visualenv.errors import ConfigError, did_you_mean

ENV_PREFIX = "visualenv-rllib:"
# the RLModule inside an Algorithm checkpoint
MODULE_DIR = Path("learner_group") / "learner" / "rl_module" / "default_policy"
# the paper's (and SB3's NatureCNN) conv stack
NATURE_FILTERS: list[list[Any]] = [
    [32, 8, 4, "valid"],
    [64, 4, 2, "valid"],
    [64, 3, 1, "valid"],
]
FEATURES = 512  # NatureCNN's features: the one dense layer both heads read


def _to_unit(observation: Any) -> np.ndarray:
    return np.asarray(observation, dtype=np.float32) * np.float32(1 / 255)


class ScaledImage(gym.ObservationWrapper):
    """uint8 images (H, W, C) -> float32 in [0, 1], the input RLlib's CNN encoder expects."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        space = env.observation_space
        self.observation_space = spaces.Box(0.0, 1.0, space.shape, np.float32)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return _to_unit(observation)


class ScaledImages(gym.vector.VectorObservationWrapper):
    """:class:`ScaledImage` for a vector env."""

    def __init__(self, env: gym.vector.VectorEnv):
        super().__init__(env)
        self.single_observation_space = spaces.Box(0.0, 1.0, env.single_observation_space.shape, np.float32)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, env.num_envs)

    def observations(self, observations: Any) -> Any:
        return _to_unit(observations)


def make_rllib_env(env_config: dict[str, Any]) -> gym.Env | gym.vector.VectorEnv:
    """One env, made where RLlib calls it (in an EnvRunner process); Blender starts at its first reset.

    `env_config` keys: ``spec`` (a path the runner's node can read), ``frame_stack``,
    ``render`` (False: the state vector, no Blender), ``threads`` (render threads), ``pin``
    (confine a remote runner's process to a core of its node that no other runner has claimed; the driver's
    process, where a user's script and the learner run, is never confined),
    ``batched`` with ``num_envs`` (RLlib adds it when it calls the vector entry point): the runner's
    envs as one BatchedVectorEnv, frames stacked by :class:`VectorFrameStack`; ``trust_code``: the spec's
    ``dynamics.python`` may be imported (the driver's consent, carried to every runner).
    """
    from visualenv.env.batch import BatchedVectorEnv
    from visualenv.env.cores import claim_core
    from visualenv.env.make import make
    from visualenv.env.wrappers import VectorFrameStack

    remote = getattr(env_config, "worker_index", 0) > 0  # a remote EnvRunner: a process Ray started for the run's envs
    if remote:
        apply_policy()  # freed memory kept for the next render call (visualenv.compat.glibc)
    spec, batched, n = env_config["spec"], env_config.get("batched", False), int(env_config.get("num_envs", 1))
    trust = bool(env_config.get("trust_code", False))
    if not env_config.get("render", True):
        if batched:
            return BatchedVectorEnv(spec, n, render=False, trust_code=trust)
        return make(spec, render=False, trust_code=trust)
    threads, frame_stack = env_config.get("threads", 1), env_config.get("frame_stack", 4)
    if remote and env_config.get("pin", True) and threads == 1:  # never the driver: its learner uses every core
        claim_core()  # before Blender starts, which sizes its thread pools to the cores it may use
    if not batched:
        return ScaledImage(make(spec, frame_stack=frame_stack, threads=threads, trust_code=trust))
    vec: gym.vector.VectorEnv = BatchedVectorEnv(spec, n, renderer_options={"threads": threads}, trust_code=trust)
    return ScaledImages(VectorFrameStack(vec, frame_stack) if frame_stack > 1 else vec)


def register(target: str, **env_config: Any) -> tuple[str, dict[str, Any]]:
    """Register a spec path or bundled id with RLlib (Ray's env registry); its name and env_config.

    The name is ``visualenv-rllib:<spec path or id>``: pass both to ``config.environment(name, env_config=...)``.
    """
    from ray.tune.registry import register_env

    from visualenv.env.registration import resolve

    resolve(target)  # a bad target fails here, in the driver
    spec = str(Path(target).resolve()) if Path(target).exists() else str(target)  # a bundled id resolves on every node
    name = ENV_PREFIX + spec
    register_env(name, make_rllib_env)
    return name, {"spec": spec, **env_config}


def conv_filters(height: int, width: int) -> list[list[Any]]:
    """Conv filters for an image of this size: SB3's NatureCNN where it fits (36 px and up), a small stack below.

    Both end in NatureCNN's 512-unit dense layer, written as a convolution whose kernel
    covers the whole last feature map: RLlib's encoder has no dense layer after its
    convolutions, and its heads would otherwise each hold their own (two 2.7M-weight
    layers where SB3 shares one).
    """
    from ray.rllib.core.models.configs import CNNEncoderConfig

    size = min(height, width)
    stack: list[list[Any]]
    if size >= 36:
        stack = NATURE_FILTERS
    elif size >= 8:
        stack = [[16, 3, 2, "valid"], [32, 3, 1, "valid"]]
    else:
        stack = [[16, 2, 1, "valid"]]
    rows, columns, _ = CNNEncoderConfig(
        input_dims=[height, width, 1], cnn_filter_specifiers=stack, flatten_at_end=False
    ).output_dims
    return [*stack, [FEATURES, [rows, columns], 1, "valid"]]


def model_config(observation_space: spaces.Space) -> Any:
    """RLlib's DefaultModelConfig for this observation: SB3's CnnPolicy for images, an MLP for a state vector.

    The CNN is initialised as SB3 initialises its NatureCNN (orthogonal, gain sqrt 2).
    With PyTorch's default initialisation, RLlib's default, four stacked Goalie frames
    gave features that hardly varied between observations, and the policy stayed
    uniform through 60k steps. (RLlib's PPO builds its two output layers with
    PyTorch's default initialisation whatever the config says.)
    """
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    shape = observation_space.shape or ()
    if len(shape) == 3:
        height, width = shape[:2]
        return DefaultModelConfig(
            conv_filters=conv_filters(height, width),  # type: ignore[arg-type]
            conv_activation="relu",
            conv_kernel_initializer="orthogonal_",
            conv_kernel_initializer_kwargs={"gain": math.sqrt(2)},
            conv_bias_initializer="zeros_",
            head_fcnet_hiddens=[],
            vf_share_layers=True,
        )
    return DefaultModelConfig(fcnet_hiddens=[64, 64], vf_share_layers=False)


def check_observation(target: str, render: bool = True, trust_code: bool = False) -> spaces.Space:
    """The observation space the model will see (no Blender started); a Dict observation is refused."""
    from visualenv.env.make import make

    env = make(target, render=render, trust_code=trust_code)
    space = env.observation_space
    env.close()
    if isinstance(space, spaces.Dict):
        raise ConfigError(
            f"{target}: --backend rllib trains on one camera; this spec's observation has several "
            f"({', '.join(space.spaces)}): RLlib's default encoder has no Dict support (use the SB3 backend)"
        )
    return space


# SB3's PPO as the SB3 backend runs it for Goalie (examples/hyperparams/goalie.yaml), in RLlib's names. Where RLlib's
# own defaults differ, SB3's are kept: RLlib clips the value loss at 10 (returns of +-10 give squared errors of
# hundreds, whose gradient the clip zeroes), adds an adaptive KL penalty and does not clip gradients.
SB3_PPO_DEFAULTS: dict[str, Any] = {
    "train_batch_size_per_learner": 512,
    "minibatch_size": 128,
    "num_epochs": 4,
    "lr": 2.5e-4,
    "gamma": 0.99,
    "lambda_": 0.95,
    "clip_param": 0.1,
    "entropy_coeff": 0.01,
    "vf_loss_coeff": 0.5,
    "vf_clip_param": float("inf"),
    "use_kl_loss": False,
    "grad_clip": 0.5,
    "grad_clip_by": "global_norm",
}
PPO_NAMES_SET_HERE = (
    "model_config",
    "learner_class",
    "learner_connector",
    "add_default_connectors_to_learner_pipeline",
)


def ppo_hyperparameters() -> list[str]:
    """The names `--set` accepts: keyword arguments of ``PPOConfig.training`` (lr, gamma, minibatch_size, ...)."""
    from ray.rllib.algorithms.ppo import PPOConfig

    names = {
        n
        for cls in PPOConfig.__mro__
        if "training" in vars(cls)
        for n in inspect.signature(vars(cls)["training"]).parameters
    }
    return sorted(names - {"self", "kwargs", *PPO_NAMES_SET_HERE})


def check_hyperparameters(hyperparams: dict[str, Any]) -> None:
    known = ppo_hyperparameters()
    for key in hyperparams:
        if key not in known:
            raise ConfigError(f"RLlib's PPO has no hyperparameter '{key}'" + did_you_mean(key, known))


def ppo_config(
    target: str,
    *,
    env_runners: int = 2,
    envs_per_runner: int = 1,
    frame_stack: int = 4,
    seed: int = 0,
    render: bool = True,
    hyperparams: dict[str, Any] | None = None,
    cpus_per_runner: int = 1,
    pin: bool = True,
    batched: bool = False,
    trust_code: bool = False,
) -> Any:
    """A PPOConfig for `target`: `env_runners` remote EnvRunners of `envs_per_runner` envs each, restarted when they die.

    `batched`: each runner's envs are one BatchedVectorEnv (one Blender scene, one render call per step)
    rather than a Gymnasium SyncVectorEnv of separate scenes. `trust_code`: the spec's ``dynamics.python`` may be
    imported, here and in every EnvRunner (docs/security.md).

    Every env renders with ``cpus_per_runner // envs_per_runner`` threads (at least one),
    so a runner uses the CPUs Ray reserves for it. Hyperparameters are ``PPOConfig.training``'s; the defaults
    are the SB3 backend's Goalie settings (examples/hyperparams/goalie.yaml) in RLlib's names.
    """
    from ray.rllib.algorithms.ppo import PPOConfig

    if env_runners < 1:
        raise ConfigError("--env-runners must be at least 1: the driver's own EnvRunner does not render")
    hyperparams = dict(hyperparams or {})
    check_hyperparameters(hyperparams)
    space = check_observation(target, render, trust_code)
    if render:
        height, width, channels = space.shape or (0, 0, 0)
        space = spaces.Box(0.0, 1.0, (height, width, channels * max(1, frame_stack)), np.float32)
    threads = cpus_per_runner if batched else max(1, cpus_per_runner // envs_per_runner)
    name, env_config = register(
        target,
        frame_stack=frame_stack,
        render=render,
        threads=threads,
        pin=pin,
        batched=batched,
        **({"trust_code": True} if trust_code else {}),
    )
    return (
        PPOConfig()
        .api_stack(enable_rl_module_and_learner=True, enable_env_runner_and_connector_v2=True)
        .environment(name, env_config=env_config)
        .env_runners(
            num_env_runners=env_runners,
            num_envs_per_env_runner=envs_per_runner,
            num_cpus_per_env_runner=cpus_per_runner,
            rollout_fragment_length="auto",
            sample_timeout_s=600.0,
            gym_env_vectorize_mode=gym.VectorizeMode.VECTOR_ENTRY_POINT if batched else gym.VectorizeMode.SYNC,
        )
        .fault_tolerance(restart_failed_env_runners=True, max_num_env_runner_restarts=100)
        .rl_module(model_config=model_config(space))
        .training(**{**SB3_PPO_DEFAULTS, **hyperparams})
        .callbacks(VisualEnvCallbacks)
        .debugging(seed=seed, log_level="ERROR")
    )


class VisualEnvCallbacks(RLlibCallback):
    """Logs each episode's success (``success_rate``) and the env steps sampled on each node (``env_steps_by_node``)."""

    def on_episode_end(self, *, episode: Any, metrics_logger: Any = None, **kwargs: Any) -> None:
        infos = episode.get_infos(-1) if hasattr(episode, "get_infos") else {}
        if metrics_logger is not None:
            metrics_logger.log_value(
                "success_rate", float(bool((infos or {}).get("is_success", False))), reduce="mean", window=100
            )

    def on_sample_end(
        self, *, env_runner: Any = None, metrics_logger: Any = None, samples: Any = None, **kwargs: Any
    ) -> None:
        import ray

        if metrics_logger is None or not samples:
            return
        steps = sum(len(episode) for episode in samples)
        metrics_logger.log_value(("env_steps_by_node", ray.get_runtime_context().get_node_id()), steps, reduce="sum")


class RLlibPolicy:
    """An RLlib RLModule behind SB3's ``predict``: what ``visualenv play`` and the final evaluation call.

    Takes the uint8 observations the env gives (stacked frames, channels last) and
    scales them as :class:`ScaledImage` does in the runners.
    """

    def __init__(self, module: Any):
        self.module = module
        space = module.observation_space
        self.scaled = len(space.shape) == 3
        self.observation_space = spaces.Box(0, 255, space.shape, np.uint8) if self.scaled else space
        self.action_space = module.action_space

    @classmethod
    def load(cls, checkpoint: str | Path) -> "RLlibPolicy":
        """The policy of an Algorithm checkpoint folder (``best_model``, ``checkpoints/latest``, ...): its pickles are
        unpickled, so only for a checkpoint the caller trusts."""
        from ray.rllib.core.rl_module.rl_module import RLModule

        with quiet_deprecations():
            return cls(RLModule.from_checkpoint(str(Path(checkpoint).resolve() / MODULE_DIR)))

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[np.ndarray, None]:
        """Actions for a batch of observations (or one), as SB3's ``predict``; `state` and `episode_start` are unused."""
        import torch

        obs = np.asarray(observation, dtype=np.float32)
        single = obs.ndim == len(self.observation_space.shape)
        if single:
            obs = obs[None]
        if self.scaled:
            obs = obs * np.float32(1 / 255)
        with torch.no_grad():
            out = self.module.forward_inference({"obs": torch.from_numpy(obs)})
        inputs = out["action_dist_inputs"]
        dist = self.module.get_inference_action_dist_cls().from_logits(inputs)
        actions = (dist.to_deterministic().sample() if deterministic else dist.sample()).numpy()
        return (actions[0] if single else actions), None


@contextmanager
def quiet_deprecations() -> Iterator[None]:
    """RLlib's deprecation warnings silenced: it warns about its own deprecated constructor while building its own modules."""
    import logging

    rllib_log = logging.getLogger(DEPRECATION_LOGGER)
    level = rllib_log.level
    rllib_log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        rllib_log.setLevel(level)


def is_checkpoint(path: str | Path) -> bool:
    """Whether `path` is an RLlib Algorithm checkpoint folder (what `visualenv train --backend rllib` saves)."""
    return (Path(path) / MODULE_DIR).is_dir()


def check_address(address: str | None) -> None:
    """An address that cannot be reached is refused before anything starts ('auto' needs a running local cluster)."""
    import socket

    if address is None or address.startswith("ray://"):
        return
    if address == "auto":
        import os

        if not os.environ.get("RAY_ADDRESS") and local_cluster_addresses() == frozenset():  # None: this Ray cannot tell
            raise ConfigError("--address auto: no Ray cluster runs on this machine (start one with `ray start --head`)")
        return
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ConfigError(f"--address {address}: expected HOST:PORT of a Ray head (e.g. 10.0.0.1:6379), or 'auto'")
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as exc:
        raise ConfigError(f"--address {address}: cannot reach a Ray head there ({exc.strerror or exc})") from None


__all__ = [
    "RLlibPolicy",
    "ScaledImage",
    "VisualEnvCallbacks",
    "check_address",
    "check_observation",
    "conv_filters",
    "is_checkpoint",
    "make_rllib_env",
    "model_config",
    "ppo_config",
    "quiet_deprecations",
    "register",
]
