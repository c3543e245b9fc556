"""Image encoders a training config may name (``policy_kwargs: {features_extractor_class: NAME}``) besides SB3's own.

* :class:`DrQEncoder`: DrQ's (Kostrikov et al. 2020; DrQ-v2 keeps it), for ``--algo sac --augment shift`` as the
  paper trains it. SB3's NatureCNN (the default) costs about a quarter of its arithmetic per frame: its first
  convolution strides by 4 where DrQ's strides by 2.

A policy file names its encoder by a key of :func:`visualenv.train.policy_kinds.features_extractors`, so each class
here is listed there. :func:`channels_last` lays out a policy's convolutions as oneDNN convolves fastest on a CPU.
"""

from __future__ import annotations

import math

import torch as th
from gymnasium import spaces
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from visualenv.errors import ConfigError


def channels_last(module: nn.Module) -> nn.Module:
    """`module` with its convolutions' weights in channels-last layout (in place; the same parameters, which its
    optimizers keep): oneDNN's own layout, in which a CPU convolves an image batch faster, forward and backward
    (results/benchmarks/drq-update-schedule-layout.md). The same arithmetic summed in another order: a policy saved
    from it (contiguous, as policy files are) acts in ``eval`` as it did in training but for float rounding."""
    return module.to(memory_format=th.channels_last)  # type: ignore[call-overload]  # torch takes it; its stubs do not say


class DrQEncoder(BaseFeaturesExtractor):
    """DrQ's encoder: four 3x3 convolutions of 32 filters (the first of stride 2, each followed by ReLU), then a linear
    layer to `features_dim`, LayerNorm and tanh, so the actor and the critic read features in [-1, 1].

    Initialised as DrQ's: linear layers orthogonal, each convolution's centre tap orthogonal with ReLU's gain and its
    other taps zero (delta-orthogonal), biases zero. Takes a channel-first uint8 image, scaled to [0, 1] by SB3 before
    it arrives (``normalized_image`` as SB3's NatureCNN).
    """

    #: the smallest image side it encodes: 15 -> 7 after the stride-2 layer, 1 after the three others
    min_side = 15

    def __init__(self, observation_space: spaces.Box, features_dim: int = 50, normalized_image: bool = False) -> None:
        if not is_image_space(observation_space, check_channels=False, normalized_image=normalized_image):
            raise ConfigError(f"DrQEncoder encodes images (a channel-first Box of uint8), not {observation_space}")
        super().__init__(observation_space, features_dim)
        channels, height, width = observation_space.shape
        self.convolutions = nn.Sequential(
            nn.Conv2d(channels, 32, 3, stride=2),
            nn.ReLU(),
            nn.Conv2d(32, 32, 3, stride=1),
            nn.ReLU(),
            nn.Conv2d(32, 32, 3, stride=1),
            nn.ReLU(),
            nn.Conv2d(32, 32, 3, stride=1),
            nn.ReLU(),
            nn.Flatten(),
        )
        size = ((height - 3) // 2 + 1 - 6, (width - 3) // 2 + 1 - 6)  # after the stride-2 and three stride-1 layers
        if min(size) < 1:
            raise ConfigError(
                f"DrQEncoder needs images of at least {self.min_side}x{self.min_side}, not {width}x{height}"
            )
        self.head = nn.Sequential(
            nn.Linear(32 * size[0] * size[1], features_dim), nn.LayerNorm(features_dim), nn.Tanh()
        )
        self.apply(_drq_init)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.head(self.convolutions(observations))


def _drq_init(module: nn.Module) -> None:
    """DrQ's ``weight_init``: orthogonal linear weights, delta-orthogonal convolutions, zero biases."""
    if isinstance(module, nn.Linear):
        nn.init.orthogonal_(module.weight)
    elif isinstance(module, nn.Conv2d):
        with th.no_grad():
            module.weight.zero_()
            middle = module.weight.shape[2] // 2
            nn.init.orthogonal_(module.weight[:, :, middle, middle], gain=math.sqrt(2))
    if isinstance(module, (nn.Linear, nn.Conv2d)) and module.bias is not None:
        nn.init.zeros_(module.bias)
