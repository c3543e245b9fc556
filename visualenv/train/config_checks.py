"""What can be wrong with a training run that is known before any env starts, each a clear error (or a note) now
rather than a torch traceback at the first update or an out-of-memory hours in: the image encoder's smallest input,
the torch device, the replay buffer's memory, and SAC's target pace under SB3's counting.

:func:`visualenv.train.sb3.check_config` runs them all.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

from visualenv.errors import ConfigError, SpecError
from visualenv.train.model_files import algorithm_class

#: a run's :class:`visualenv.train.sb3.TrainConfig` (not imported: sb3 imports these checks)
TrainConfig = Any

# SB3's NatureCNN: 8x8 stride 4, 4x4 stride 2, 3x3 convolutions leave nothing of smaller images
NATURE_CNN_MIN_SIZE = 36


def check_cnn_input(loaded: Any, policy_kwargs: dict[str, Any] | None) -> None:
    """Observations too small for the run's image encoder (SB3's NatureCNN, or a listed one with a ``min_side``) are a
    located error before any run folder, not a torch RuntimeError at the first update."""
    encoder = (policy_kwargs or {}).get("features_extractor_class")
    smallest = NATURE_CNN_MIN_SIZE if encoder is None else getattr(encoder, "min_side", None)
    observation = loaded.spec.observation
    if observation is None or smallest is None:
        return
    name = "SB3's NatureCNN" if encoder is None else encoder.__name__
    problems = []
    for key, view in observation.views().items():
        width, height = view.resolution
        if min(width, height) < smallest:
            where = ("cameras", key) if observation.cameras is not None else ()
            message = f"{width}x{height} is too small for the CNN policy of `visualenv train` ({name}): it needs"
            problems.append(
                loaded.source.diagnostic(
                    ("observation", *where, "resolution"), f"{message} at least {smallest}x{smallest}"
                )
            )
    if problems:
        raise SpecError(problems)


def check_torch_device(device: Any) -> None:
    """A device torch does not know, or a CUDA device where torch has none, is an error now, not a traceback once the
    envs have started."""
    import torch

    if device == "auto":
        return
    try:
        kind = torch.device(device).type
    except (RuntimeError, TypeError):
        raise ConfigError(f"device {device!r}: expected auto, cpu, cuda or cuda:N (a torch device)") from None
    if kind != "cuda":
        return

    if not torch.cuda.is_available():
        build = f"built for CUDA {torch.version.cuda}" if torch.version.cuda else "a CPU-only build"
        raise ConfigError(
            f"device '{device}': torch {torch.__version__} ({build}) sees no CUDA device on this machine; "
            "use --device cpu (or auto), or install a CUDA build of torch where a GPU is"
        )


#: the share of the available memory a run's stored observations may take (a replay buffer, distill's frames): the
#: envs, the model and its batches need the rest
STORED_MEMORY_SHARE = 0.7


def memory_room() -> tuple[float, int]:
    """The bytes a run's stored observations may take on this machine now (:data:`STORED_MEMORY_SHARE` of the
    available memory), and the available bytes, for the message that refuses more."""
    import psutil

    available = int(psutil.virtual_memory().available)
    return STORED_MEMORY_SHARE * available, available


def replay_buffer_bytes(config: TrainConfig, kwargs: dict[str, Any], loaded: Any) -> int | None:
    """What an off-policy algorithm's replay buffer will hold at most, in bytes; None for an on-policy algorithm.

    SB3 stores each observation and the next one (``optimize_memory_usage`` and ``--augment``'s buffer keep
    one: consecutive samples share it), as uint8 images (frames stacked) or float32 states.
    """
    import inspect

    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

    algo = algorithm_class(config.algo)
    if not issubclass(algo, OffPolicyAlgorithm):
        return None
    defaults = inspect.signature(algo.__init__).parameters
    size = int(kwargs.get("buffer_size", defaults["buffer_size"].default))
    optimized = bool(config.augment or kwargs.get("optimize_memory_usage", defaults["optimize_memory_usage"].default))
    observation = loaded.spec.observation
    if config.render and observation is not None:
        channels = {"rgb": 3, "grayscale": 1, "depth": 1}
        per_sample = sum(
            w * h * channels[v.color] * max(1, config.frame_stack)
            for v in observation.views().values()
            for w, h in [v.resolution]
        )
    else:
        per_sample = 4 * sum(1 for var in loaded.spec.state.values() if var.observe)
    return size * per_sample * (1 if optimized else 2)


def check_replay_buffer(config: TrainConfig, kwargs: dict[str, Any], loaded: Any) -> None:
    """A replay buffer of image stacks that cannot fit in memory is refused before any env starts (SB3 would only warn, then fail hours later)."""
    need = replay_buffer_bytes(config, kwargs, loaded)
    if need is None:
        return
    room, available = memory_room()
    if need > room:
        fits = int(room // (replay_buffer_bytes(config, {**kwargs, "buffer_size": 1}, loaded) or 1))
        raise ConfigError(
            f"{config.algo.upper()}'s replay buffer would take {need / 2**30:.1f} GiB, and "
            f"{available / 2**30:.1f} GiB of memory "
            f"are available: set buffer_size={fits:,} or less (--set buffer_size={fits})"
            + (
                ""
                if config.augment
                else ", or optimize_memory_usage=true (one copy of each observation; SB3 then needs "
                "replay_buffer_kwargs: {handle_timeout_termination: false})"
            )
        )


def check_target_pace(config: TrainConfig, kwargs: dict[str, Any]) -> None:
    """Warn where SAC's ``target_update_interval`` will not set the pace it says: SB3 counts it within each update
    call (``gradient_step % target_update_interval``, SB3 issue 2158), so with G updates a call the target moves
    ceil(G / interval) times per G updates, not once per interval. DrQ's SAC (``--augment``) counts across calls."""
    interval = int(kwargs.get("target_update_interval", 1))
    if config.algo != "sac" or config.augment is not None or interval <= 1:
        return
    steps, frequency = kwargs.get("gradient_steps", 1), kwargs.get("train_freq", 1)
    if isinstance(frequency, (list, tuple)):
        if str(frequency[1]) != "step":
            return  # a call per episode: its updates vary
        frequency = frequency[0]
    per_call = int(steps) if int(steps) > 0 else int(frequency) * max(1, config.envs)
    if per_call % interval == 0:
        return
    tau = float(kwargs.get("tau", 0.005))
    warnings.warn(
        f"SAC's target_update_interval={interval} counts updates within each update call (SB3 issue 2158), and each "
        f"call here makes {per_call}: the target network moves {math.ceil(per_call / interval)} time(s) in each "
        f"call's {per_call} update(s), not once every {interval}. For that pace set target_update_interval=1 and "
        f"tau={tau / interval:g}.",
        stacklevel=3,  # check_config's caller
    )
