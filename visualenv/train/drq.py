"""`visualenv train --augment shift`: DrQ's random shift of image observations, for SAC and PPO.

* :func:`random_shift`: each image padded by 4 pixels (its edge pixels repeated) and cropped back at a random
  offset, drawn per sample (DrQ, Kostrikov et al. 2020);
* SAC: :class:`DrQReplayBuffer` keeps each frame once (uint8) and shifts the observations and the next observations of
  every sampled batch independently; :class:`DrQSACPolicy` shares the encoder's convolutions between actor and
  critic, trained by the critic's loss only, and gives the actor its own head on their detached output (DrQ ties the
  convolutions alone: ``copy_conv_weights_from``); :class:`DrQSAC` updates them on DrQ's schedule (the actor and the
  target every few critic updates, counted across SB3's update calls);
* PPO: :class:`ShiftedRolloutBuffer` shifts the observations of each minibatch (as RAD and DrAC do).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3 import SAC
from stable_baselines3.common.buffers import ReplayBuffer, RolloutBuffer
from stable_baselines3.common.policies import ContinuousCritic
from stable_baselines3.common.preprocessing import is_image_space, is_image_space_channels_first, preprocess_obs
from stable_baselines3.common.torch_layers import NatureCNN
from stable_baselines3.common.type_aliases import ReplayBufferSamples, RolloutBufferSamples
from stable_baselines3.common.utils import polyak_update
from stable_baselines3.sac.policies import Actor, CnnPolicy

from visualenv.compat.sb3 import batch_discounts, count_updates, sample_batch, start_updates, updates_made
from visualenv.errors import ConfigError
from visualenv.train.encoders import DrQEncoder

AUGMENTS = ("shift",)
PAD = 4  # DrQ's padding: shifts of up to 4 pixels each way on 84x84 frames
ALGORITHMS = ("ppo", "sac")  # those `--augment` trains


def random_shift(images: th.Tensor, pad: int = PAD, *, channels_first: bool = True) -> th.Tensor:
    """Each image of the batch moved by its own random offset of up to `pad` pixels each way, the pixels it uncovers
    repeating its edge: DrQ's replicate-pad then random crop back to the image's size. Any dtype (uint8 frames stay
    uint8, the pixels only move); `images` is (N, C, H, W), or (N, H, W, C) where not `channels_first`."""
    if pad == 0 or images.shape[0] == 0:
        return images
    batch = images if channels_first else images.permute(0, 3, 1, 2)
    dy, dx = th.randint(-pad, pad + 1, (2, batch.shape[0]), device=batch.device)
    shifted = crop_padded(batch, pad, (dy + pad).tolist(), (dx + pad).tolist())
    return shifted if channels_first else shifted.permute(0, 2, 3, 1)


def crop_padded(images: th.Tensor, pad: int, tops: Sequence[int], lefts: Sequence[int]) -> th.Tensor:
    """Each (C, H, W) image of `images` padded by `pad` pixels (its edge repeated) and cropped back to H x W with its
    top-left corner at (tops[i], lefts[i]) of the padded image, each in [0, 2 pad]: one copy per crop."""
    n, c, h, w = images.shape
    padded = F.pad(images, (pad, pad, pad, pad), mode="replicate")
    shifted = th.empty((n, c, h, w), dtype=images.dtype, device=images.device)
    for i, (top, left) in enumerate(zip(tops, lefts)):
        shifted[i] = padded[i, :, top : top + h, left : left + w]
    return shifted


def shift_observations(observations: th.Tensor, space: spaces.Space, pad: int = PAD) -> th.Tensor:
    """A batch of observations of the image space `space` (channel-first as SB3 transposes it, or channel-last)
    shifted by :func:`random_shift`."""
    return random_shift(observations, pad, channels_first=is_image_space_channels_first(space))  # type: ignore[arg-type]


def check_augment(augment: str | None, algo: str, render: bool, loaded: Any) -> None:
    """`--augment` of a run, refused now (before any env starts) where it cannot apply: another augmentation, another
    algorithm, a state-only run, or a spec whose observation is not one image."""
    if augment is None:
        return
    if augment not in AUGMENTS:
        raise ConfigError(f"--augment {augment}: expected one of {', '.join(AUGMENTS)}")
    if algo not in ALGORITHMS:
        raise ConfigError(f"--augment {augment}: for --algo {' or '.join(ALGORITHMS)}, not {algo}")
    observation = loaded.spec.observation
    if not render or observation is None:
        raise ConfigError(f"--augment {augment} shifts image observations: a state-only run has none")
    if len(observation.views()) != 1:
        raise ConfigError(
            f"--augment {augment} shifts one image per observation; {loaded.spec.id} observes "
            f"{len(observation.views())} cameras"
        )


def model_arguments(algo: str, augment: str | None, policy: Any) -> tuple[Any, dict[str, Any]]:
    """The policy and the extra keyword arguments of the SB3 algorithm that `augment` asks for: SAC gets DrQ's policy
    and buffer, PPO its shifting rollout buffer; without `augment`, `policy` and none."""
    if augment is None:
        return policy, {}
    if algo == "sac":
        return DrQSACPolicy, {"replay_buffer_class": DrQReplayBuffer}
    return policy, {"rollout_buffer_class": ShiftedRolloutBuffer}


def _image_space(space: spaces.Space) -> None:
    if not is_image_space(space, check_channels=False):
        raise ConfigError(f"--augment shift shifts images (uint8 Box of height, width and channels), not {space}")


# -- SAC: DrQ -------------------------------------------------------------------------------------------------------


class DrQReplayBuffer(ReplayBuffer):
    """SB3's replay buffer of uint8 frames, each observation stored once, timeouts handled, batches shifted.

    A transition's next observation is the next slot's observation (as SB3's ``optimize_memory_usage``), except at the
    end of an episode cut by its time limit, where the next slot holds the reset's frame: that final observation,
    which the critic's target bootstraps from, is kept aside (one frame per such episode end). SB3's own
    ``optimize_memory_usage`` cannot do this and refuses ``handle_timeout_termination``. The memory the buffer takes
    is printed before it is allocated.
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        device: th.device | str = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = True,  # always: each observation once
        handle_timeout_termination: bool = True,
        pad: int = PAD,
    ):
        _image_space(observation_space)
        print(f"replay buffer: {buffer_memory(buffer_size, observation_space, action_space)}", flush=True)
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device,
            n_envs,
            optimize_memory_usage=True,
            handle_timeout_termination=False,  # SB3 refuses it with optimize_memory_usage; set below
        )
        self.handle_timeout_termination = handle_timeout_termination
        self.pad = pad
        self.has_final = np.zeros((self.buffer_size, self.n_envs), dtype=bool)
        self.final_observations: dict[tuple[int, int], np.ndarray] = {}

    def add(
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        pos = self.pos
        for env in np.flatnonzero(self.has_final[pos]):  # the slot's earlier transition is overwritten
            self.final_observations.pop((pos, int(env)), None)
        self.has_final[pos] = False
        super().add(obs, next_obs, action, reward, done, infos)
        if self.handle_timeout_termination:
            for env in np.flatnonzero(np.asarray(done) * self.timeouts[pos]):
                self.final_observations[(pos, int(env))] = np.array(next_obs[env], dtype=self.observations.dtype)
                self.has_final[pos, env] = True

    def kept_arrays(self) -> dict[str, np.ndarray]:
        """The final frames kept aside, stacked, and their (slot, env): what a checkpoint saves besides SB3's rows."""
        slots = sorted(self.final_observations)
        frames = [self.final_observations[slot] for slot in slots]
        return {
            "final_observations": np.stack(frames)
            if frames
            else np.zeros((0, *self.obs_shape), self.observations.dtype),
            "final_slots": np.array(slots, dtype=np.int64).reshape(-1, 2),
        }

    def restore_kept(self, frames: np.ndarray, slots: np.ndarray) -> None:
        """Put back the final frames :meth:`kept_arrays` gave (a checkpoint's, checked by the caller)."""
        self.final_observations = {(int(i), int(e)): np.array(frame) for (i, e), frame in zip(slots, frames)}
        self.has_final[:] = False
        for i, e in self.final_observations:
            self.has_final[i, e] = True

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> ReplayBufferSamples:
        env_indices = np.random.randint(0, high=self.n_envs, size=(len(batch_inds),))
        next_obs = self.observations[(batch_inds + 1) % self.buffer_size, env_indices]
        for k in np.flatnonzero(self.has_final[batch_inds, env_indices]):
            next_obs[k] = self.final_observations[(int(batch_inds[k]), int(env_indices[k]))]
        rewards = self.rewards[batch_inds, env_indices].reshape(-1, 1)
        data = (
            self.observations[batch_inds, env_indices],
            self.actions[batch_inds, env_indices, :],
            next_obs,
            (self.dones[batch_inds, env_indices] * (1 - self.timeouts[batch_inds, env_indices])).reshape(-1, 1),
            rewards if env is None else env.normalize_reward(rewards).astype(np.float32),  # SB3's, without VecNormalize
        )
        samples = ReplayBufferSamples(*tuple(map(self.to_torch, data)))
        return samples._replace(
            observations=shift_observations(samples.observations, self.observation_space, self.pad),
            next_observations=shift_observations(samples.next_observations, self.observation_space, self.pad),
        )


def buffer_memory(buffer_size: int, observation_space: spaces.Space, action_space: spaces.Space) -> str:
    """What a :class:`DrQReplayBuffer` of `buffer_size` transitions takes, in words."""
    shape = observation_space.shape or ()
    frame = int(np.prod(shape)) * np.dtype(observation_space.dtype).itemsize
    per_transition = frame + 4 * (int(np.prod(action_space.shape or (1,))) + 3)  # action, reward, done, timeout
    total = buffer_size * per_transition
    return (
        f"{buffer_size:,} transitions of {'x'.join(map(str, shape))} "
        f"{np.dtype(observation_space.dtype).name} observations, each stored once: "
        + (f"{total / 2**30:.1f} GiB " if total >= 2**30 else f"{total / 2**20:.1f} MiB ")
        + "(and one frame per episode cut by its time limit)"
    )


#: each listed encoder's convolutions (shared by the actor and the critic) and its head (one each), by attribute
ENCODER_PARTS: dict[type, tuple[str, str]] = {NatureCNN: ("cnn", "linear"), DrQEncoder: ("convolutions", "head")}


def _part_names(encoder: Any) -> tuple[str, str] | None:
    return next((parts for kind, parts in ENCODER_PARTS.items() if isinstance(encoder, kind)), None)


def encoder_parts(encoder: Any) -> tuple[Any, Any] | None:
    """An encoder's convolutions and head, where its kind is known (:data:`ENCODER_PARTS`); None for any other, which
    the actor and the critic share whole."""
    names = _part_names(encoder)
    return None if names is None else (getattr(encoder, names[0]), getattr(encoder, names[1]))


class DrQActor(Actor):
    """SB3's SAC actor on the shared convolutions' output, detached, through its own head: the actor's loss trains its
    head and not the convolutions (an encoder of another kind is read whole, detached)."""

    def extract_features(self, obs: Any, features_extractor: Any) -> th.Tensor:  # type: ignore[override]
        parts = encoder_parts(features_extractor)
        if parts is None:
            return super().extract_features(obs, features_extractor).detach()
        convolutions, head = parts
        images = preprocess_obs(obs, self.observation_space, normalize_images=self.normalize_images)
        return head(convolutions(images).detach())


class DrQCritic(ContinuousCritic):
    """SB3's SAC critic whose encoder learns from the critic's loss; in the actor's loss (actions drawn by the actor,
    which carry gradients) it reads the features detached, as DrQ's critic does there."""

    def forward(self, obs: th.Tensor, actions: th.Tensor) -> tuple[th.Tensor, ...]:
        features = self.extract_features(obs, self.features_extractor)
        if actions.requires_grad:
            features = features.detach()
        qvalue_input = th.cat([features, actions], dim=1)
        return tuple(q_net(qvalue_input) for q_net in self.q_networks)


class DrQSACPolicy(CnnPolicy):
    """SB3's SAC CnnPolicy built as DrQ's: the encoder's convolutions (NatureCNN's, or those of the encoder the config
    names) shared by actor and critic, in the critic's optimizer and not in the actor's; the actor and the critic each
    with their own head on them (DrQ's linear layer and LayerNorm); the target critic with its own copy of all of it,
    updated with the Q heads by SB3's soft update (`tau`). ``share_features_extractor`` is not read."""

    def make_actor(self, features_extractor: Any = None) -> Actor:
        return DrQActor(**self.with_encoder(self.actor_kwargs, features_extractor)).to(self.device)

    def make_critic(self, features_extractor: Any = None) -> ContinuousCritic:
        return DrQCritic(**self.with_encoder(self.critic_kwargs, features_extractor)).to(self.device)

    def with_encoder(self, kwargs: dict[str, Any], encoder: Any) -> dict[str, Any]:
        """The actor's or critic's arguments with `encoder`, or a new one (what SB3's policies do for themselves)."""
        encoder = encoder if encoder is not None else self.make_features_extractor()
        return {**kwargs, "features_extractor": encoder, "features_dim": encoder.features_dim}

    def _build(self, lr_schedule: Any) -> None:
        self.actor = self.make_actor()
        encoder = self.actor.features_extractor
        names = _part_names(encoder)
        if names is None:  # an encoder of another kind: shared whole
            critic_encoder = shared = encoder
        else:  # the critic's own head on the actor's convolutions
            critic_encoder, shared = self.make_features_extractor(), getattr(encoder, names[0])
            setattr(critic_encoder, names[0], shared)
        self.critic = self.make_critic(features_extractor=critic_encoder)
        self.critic_target = self.make_critic(features_extractor=None)
        self.critic_target.load_state_dict(self.critic.state_dict())
        in_common = {id(p) for p in shared.parameters()}
        self.actor.optimizer = self.optimizer_class(
            [p for p in self.actor.parameters() if id(p) not in in_common],
            lr=lr_schedule(1),  # type: ignore[call-arg]
            **self.optimizer_kwargs,
        )
        self.critic.optimizer = self.optimizer_class(
            self.critic.parameters(),
            lr=lr_schedule(1),  # type: ignore[call-arg]
            **self.optimizer_kwargs,
        )
        self.critic_target.set_training_mode(False)


class DrQSAC(SAC):
    """SB3's SAC on DrQ's update schedule (``DRQAgent.update``): each update trains the critic on a batch; every
    `actor_update_interval`-th update then trains the actor and the temperature on the same batch, and every
    `target_update_interval`-th moves the target critic by `tau`. Updates are counted across SB3's update calls
    (its SAC counts the target's interval within each call: SB3 issue 2158), so DrQ's ``tau: 0.01`` every 2 updates
    and an actor every 2 updates are set as DrQ sets them. The losses are SB3's SAC's (the temperature learns its
    log, as SB3's does)."""

    def __init__(self, *args: Any, actor_update_interval: int = 1, **kwargs: Any) -> None:
        if isinstance(actor_update_interval, bool) or not isinstance(actor_update_interval, int):
            raise ValueError(f"actor_update_interval: expected a whole number, got {actor_update_interval!r}")
        if actor_update_interval < 1:
            raise ValueError(f"actor_update_interval: expected 1 or more, got {actor_update_interval}")
        self.actor_update_interval = actor_update_interval
        super().__init__(*args, **kwargs)

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        optimizers = [self.actor.optimizer, self.critic.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers.append(self.ent_coef_optimizer)
        start_updates(self, optimizers)
        logged: dict[str, list[float]] = {"critic_loss": [], "actor_loss": [], "ent_coef": [], "ent_coef_loss": []}
        for _ in range(gradient_steps):
            update = updates_made(self)
            batch = sample_batch(self, batch_size)
            ent_coef = self._temperature()
            logged["ent_coef"].append(ent_coef.item())
            logged["critic_loss"].append(self._train_critic(batch, ent_coef))
            if update % self.actor_update_interval == 0:
                logged["actor_loss"].append(self._train_actor(batch, ent_coef, logged["ent_coef_loss"]))
            if update % self.target_update_interval == 0:
                polyak_update(self.critic.parameters(), self.critic_target.parameters(), self.tau)
                polyak_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)
            count_updates(self, 1)
        self.logger.record("train/n_updates", updates_made(self), exclude="tensorboard")
        for name, values in logged.items():
            if values:
                self.logger.record(f"train/{name}", float(np.mean(values)))

    def _temperature(self) -> th.Tensor:
        """SAC's entropy coefficient now, out of any graph."""
        if self.log_ent_coef is not None:
            return th.exp(self.log_ent_coef.detach())
        return self.ent_coef_tensor

    def _train_critic(self, batch: ReplayBufferSamples, ent_coef: th.Tensor) -> float:
        """One step of the critic (its encoder's convolutions included) toward the soft Bellman target."""
        if self.use_sde:
            self.actor.reset_noise()
        with th.no_grad():
            next_actions, next_log_prob = self.actor.action_log_prob(batch.next_observations)
            next_q = th.cat(self.critic_target(batch.next_observations, next_actions), dim=1).amin(dim=1, keepdim=True)
            next_q = next_q - ent_coef * next_log_prob.reshape(-1, 1)
            target = batch.rewards + (1 - batch.dones) * batch_discounts(batch, self.gamma) * next_q
        current = self.critic(batch.observations, batch.actions)
        loss = 0.5 * sum(F.mse_loss(q, target) for q in current)
        self.critic.optimizer.zero_grad()
        loss.backward()  # type: ignore[union-attr]
        self.critic.optimizer.step()
        return float(loss.item())  # type: ignore[union-attr]

    def _train_actor(self, batch: ReplayBufferSamples, ent_coef: th.Tensor, ent_coef_losses: list[float]) -> float:
        """One step of the actor (on the critic's features, detached) and of the temperature, on the critic just
        trained."""
        actions, log_prob = self.actor.action_log_prob(batch.observations)
        log_prob = log_prob.reshape(-1, 1)
        q = th.cat(self.critic(batch.observations, actions), dim=1).amin(dim=1, keepdim=True)
        loss = (ent_coef * log_prob - q).mean()
        self.actor.optimizer.zero_grad()
        loss.backward()
        self.actor.optimizer.step()
        if self.ent_coef_optimizer is not None and self.log_ent_coef is not None:
            ent_coef_loss = -(self.log_ent_coef * (log_prob + float(self.target_entropy)).detach()).mean()
            self.ent_coef_optimizer.zero_grad()
            ent_coef_loss.backward()
            self.ent_coef_optimizer.step()
            ent_coef_losses.append(float(ent_coef_loss.item()))
        return float(loss.item())


# -- PPO: RAD / DrAC ------------------------------------------------------------------------------------------------


class ShiftedRolloutBuffer(RolloutBuffer):
    """SB3's rollout buffer whose minibatches carry shifted observations (the log-probabilities and values of the
    rollout stay those of the frames the policy acted on)."""

    def __init__(self, *args: Any, pad: int = PAD, **kwargs: Any):
        super().__init__(*args, **kwargs)
        _image_space(self.observation_space)
        self.pad = pad

    def _get_samples(self, batch_inds: np.ndarray, env: Any = None) -> RolloutBufferSamples:
        samples = super()._get_samples(batch_inds, env)
        return samples._replace(observations=shift_observations(samples.observations, self.observation_space, self.pad))
