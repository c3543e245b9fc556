"""`train --augment shift` without rendering: DrQ's random shift, its replay and rollout buffers, and the SAC policy
whose shared encoder learns from the critic only (visualenv.train.drq)."""

import json

import gymnasium as gym
import numpy as np
import pytest
import torch
from click.testing import CliRunner
from gymnasium import spaces

from visualenv.cli import main
from visualenv.errors import ConfigError
from visualenv.train.drq import (
    PAD,
    DrQReplayBuffer,
    DrQSAC,
    DrQSACPolicy,
    ShiftedRolloutBuffer,
    model_arguments,
    random_shift,
)
from visualenv.train.model_files import algorithm_class


def _pattern(n: int, c: int = 2, h: int = 20, w: int = 24) -> torch.Tensor:
    """A batch of images whose every pixel is distinct within its channel (row * w + column), as int64."""
    image = torch.arange(h * w).reshape(h, w)
    return torch.stack([image + 1000 * k for k in range(c)])[None].repeat(n, 1, 1, 1)


def _shift_of(original: np.ndarray, shifted: np.ndarray, pad: int) -> tuple[int, int]:
    """The (dy, dx) for which `shifted` is `original` edge-padded by `pad` and cropped at that offset; fails if none."""
    _, h, w = original.shape
    padded = np.pad(original, ((0, 0), (pad, pad), (pad, pad)), mode="edge")
    found = [
        (dy, dx)
        for dy in range(-pad, pad + 1)
        for dx in range(-pad, pad + 1)
        if np.array_equal(padded[:, pad + dy : pad + dy + h, pad + dx : pad + dx + w], shifted)
    ]
    assert len(found) == 1, "not a replicate-padded crop of the image"
    return found[0]


def test_the_shift_moves_each_image_by_at_most_4_pixels_its_edges_repeated_and_differs_across_samples():
    torch.manual_seed(0)
    images = _pattern(64)
    shifted = random_shift(images)
    assert shifted.shape == images.shape and shifted.dtype == images.dtype
    shifts = [_shift_of(images[i].numpy(), shifted[i].numpy(), PAD) for i in range(64)]
    assert all(abs(dy) <= PAD and abs(dx) <= PAD for dy, dx in shifts)
    assert len(set(shifts)) > 20  # drawn per sample: 81 possible offsets
    # uint8 frames stay uint8, channel-last images move the same way
    frames = torch.randint(0, 256, (8, 12, 12, 3), dtype=torch.uint8)
    moved = random_shift(frames, channels_first=False)
    assert moved.dtype == torch.uint8 and moved.shape == frames.shape
    for i in range(8):
        _shift_of(frames[i].permute(2, 0, 1).numpy(), moved[i].permute(2, 0, 1).numpy(), PAD)


def test_the_shift_draws_the_offsets_drqs_gather_would_and_moves_the_same_pixels():
    """The pad-and-copy shift against a gather of clamped rows and columns (an image's edge repeated), from the same
    random draws, for uint8 and float frames."""
    for dtype in (torch.uint8, torch.float32):
        images = (torch.rand(16, 9, 20, 24) * 255).to(dtype)
        torch.manual_seed(3)
        shifted = random_shift(images)
        torch.manual_seed(3)
        dy, dx = torch.randint(-PAD, PAD + 1, (2, 16))
        rows = (torch.arange(20)[None] + dy[:, None]).clamp(0, 19)
        cols = (torch.arange(24)[None] + dx[:, None]).clamp(0, 23)
        gathered = images[
            torch.arange(16)[:, None, None, None],
            torch.arange(9)[None, :, None, None],
            rows[:, None, :, None],
            cols[:, None, None, :],
        ]
        assert torch.equal(shifted, gathered)


IMAGE = spaces.Box(0, 255, (3, 40, 40), np.uint8)  # channel-first, as SB3 transposes it
ACTION = spaces.Box(-1.0, 1.0, (2,), np.float32)


def test_the_replay_buffer_keeps_each_frame_once_and_the_final_frame_of_a_timeout(capsys):
    buffer = DrQReplayBuffer(10, IMAGE, ACTION, device="cpu", n_envs=1, pad=0)
    assert "replay buffer: 10 transitions of 3x40x40 uint8 observations, each stored once" in capsys.readouterr().out
    assert buffer.handle_timeout_termination and getattr(buffer, "next_observations", None) is None
    frames = [np.full((1, 3, 40, 40), k, np.uint8) for k in range(8)]
    final = np.full((1, 3, 40, 40), 99, np.uint8)  # the frame an episode cut by its time limit ends on
    for k in range(6):
        timeout = k == 3
        buffer.add(
            frames[k],
            final if timeout else frames[k + 1],
            np.zeros((1, 2)),
            np.ones(1),
            np.array([timeout]),
            [{"TimeLimit.truncated": timeout}],
        )
    samples = buffer._get_samples(np.arange(5))
    next_first = samples.next_observations[:, 0, 0, 0].tolist()
    assert samples.observations[:, 0, 0, 0].tolist() == [0, 1, 2, 3, 4]
    assert next_first == [1, 2, 3, 99, 5]  # slot 4's frame is the reset's, not the final one
    assert samples.dones.flatten().tolist() == [0, 0, 0, 0, 0]  # a timeout bootstraps
    for _ in range(10):  # the slot is overwritten: its final frame goes
        buffer.add(frames[0], frames[0], np.zeros((1, 2)), np.ones(1), np.array([False]), [{}])
    assert not buffer.final_observations and not buffer.has_final.any()


def test_the_replay_buffer_shifts_observations_and_next_observations_independently():
    torch.manual_seed(0)
    buffer = DrQReplayBuffer(64, IMAGE, ACTION, device="cpu", n_envs=1)
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, (1, 3, 40, 40), dtype=np.uint8)
    for _ in range(40):
        buffer.add(frame, frame, np.zeros((1, 2)), np.ones(1), np.array([False]), [{}])
    samples = buffer.sample(16)
    assert samples.observations.dtype == torch.uint8
    obs = [_shift_of(frame[0], samples.observations[i].numpy(), PAD) for i in range(16)]
    nxt = [_shift_of(frame[0], samples.next_observations[i].numpy(), PAD) for i in range(16)]
    assert obs != nxt and len(set(obs)) > 4


def test_ppo_minibatches_carry_shifted_observations():
    torch.manual_seed(0)
    buffer = ShiftedRolloutBuffer(8, IMAGE, ACTION, device="cpu", n_envs=1)
    frame = np.random.default_rng(1).integers(0, 256, (1, 3, 40, 40), dtype=np.uint8)
    for _ in range(8):
        buffer.add(frame, np.zeros((1, 2)), np.zeros(1), np.array([False]), torch.zeros(1), torch.zeros(1))
    buffer.compute_returns_and_advantage(torch.zeros(1), np.array([False]))
    (batch,) = buffer.get(8)
    shifts = [_shift_of(frame[0].astype(np.float32), batch.observations[i].numpy(), PAD) for i in range(8)]
    assert len(set(shifts)) > 1
    with pytest.raises(ConfigError, match="--augment shift shifts images"):
        ShiftedRolloutBuffer(8, spaces.Box(-1, 1, (5,), np.float32), ACTION, device="cpu")


class _Frames(gym.Env):
    """A tiny image env: random 40x40 RGB frames, a reward for the first action's sign."""

    observation_space = spaces.Box(0, 255, (40, 40, 3), np.uint8)
    action_space = ACTION

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), float(action[0] > 0), False, False, {}


def _sac(**kwargs):
    """DrQ's SAC as `train --algo sac --augment shift` builds it, its buffer filled, no update made yet."""
    policy, extra = model_arguments("sac", "shift", "CnnPolicy")
    model = algorithm_class("sac", "shift")(
        policy, _Frames(), buffer_size=64, learning_starts=16, batch_size=8, seed=0, device="cpu", **kwargs, **extra
    )
    model.learn(16)  # fills the buffer
    return model


def _params(module):
    return [p.detach().clone() for p in module.parameters()]


def test_the_convolutions_are_shared_and_learn_from_the_critics_loss_only():
    """DrQ's sharing: one set of convolutions for actor and critic, trained by the critic's loss; each has its own head
    on them (the actor's trained by the actor's loss, on the convolutions' output detached); the target its own copy."""
    model = _sac()
    policy = model.policy
    assert isinstance(policy, DrQSACPolicy)
    actor, critic = policy.actor.features_extractor, policy.critic.features_extractor
    convolutions = critic.cnn  # SB3's NatureCNN: convolutions (cnn), then the head (linear)
    assert actor.cnn is convolutions and actor.linear is not critic.linear
    assert policy.critic_target.features_extractor.cnn is not convolutions
    in_actor = {id(p) for group in policy.actor.optimizer.param_groups for p in group["params"]}
    in_critic = {id(p) for group in policy.critic.optimizer.param_groups for p in group["params"]}
    assert all(id(p) in in_critic and id(p) not in in_actor for p in convolutions.parameters())
    assert all(id(p) in in_actor and id(p) not in in_critic for p in actor.linear.parameters())

    # an actor loss (the policy's, as SAC computes it) puts no gradient on the convolutions, and one on the actor's
    # head; a critic loss puts one on the convolutions
    batch = model.replay_buffer.sample(8)
    policy.zero_grad(set_to_none=True)
    actions, log_prob = policy.actor.action_log_prob(batch.observations)
    q = torch.cat(policy.critic(batch.observations, actions), dim=1).min(dim=1).values
    (0.1 * log_prob - q).mean().backward()
    assert all(p.grad is None or not p.grad.any() for p in convolutions.parameters())
    assert all(p.grad is None or not p.grad.any() for p in critic.linear.parameters())
    assert any(p.grad is not None and p.grad.any() for p in actor.linear.parameters())
    assert any(p.grad is not None and p.grad.any() for p in policy.actor.mu.parameters())
    sum(q.pow(2).mean() for q in policy.critic(batch.observations, batch.actions)).backward()
    assert all(p.grad is not None for p in convolutions.parameters())
    assert any(p.grad.any() for p in convolutions.parameters())

    # one SAC train step moves the convolutions; with the critic's optimizer stilled, the actor's step leaves them be
    # and moves its own head
    before = _params(convolutions)
    model.train(gradient_steps=1, batch_size=8)
    assert any(not torch.equal(a, b) for a, b in zip(before, _params(convolutions)))
    before, head_before = _params(convolutions), _params(actor.linear)
    policy.critic.optimizer.step = lambda *args, **kwargs: None
    model.train(gradient_steps=1, batch_size=8)
    assert all(torch.equal(a, b) for a, b in zip(before, _params(convolutions)))
    assert any(not torch.equal(a, b) for a, b in zip(head_before, _params(actor.linear)))


def test_drqs_sac_trains_the_actor_and_moves_the_target_on_drqs_schedule_across_update_calls():
    """DrQ's schedule (``DRQAgent.update``): the critic at every update; the actor and the temperature, and the target
    critic's move, at updates 0, 2, 4... counted across train() calls (SB3's SAC, one update a call, counts each call
    from 0 and would move the target at every one: SB3 issue 2158)."""
    model = _sac(actor_update_interval=2, target_update_interval=2, tau=0.01)
    assert isinstance(model, DrQSAC) and model.actor_update_interval == 2
    policy = model.policy
    parts = {
        "critic": policy.critic,
        "actor": policy.actor.mu,
        "target": policy.critic_target,
        "temperature": [model.log_ent_coef],
    }

    def values():
        return {name: [p.detach().clone() for p in _parameters(part)] for name, part in parts.items()}

    moved: dict[str, list[bool]] = {name: [] for name in parts}
    for _ in range(5):
        before = values()
        model.train(gradient_steps=1, batch_size=8)
        after = values()
        for name in parts:
            moved[name].append(any(not torch.equal(a, b) for a, b in zip(before[name], after[name])))
    assert moved["critic"] == [True] * 5
    assert moved["actor"] == moved["temperature"] == moved["target"] == [True, False, True, False, True]
    logged = model.logger.name_to_value
    assert logged["train/n_updates"] == 5 and "train/critic_loss" in logged

    with pytest.raises(ValueError, match="actor_update_interval: expected 1 or more"):
        _sac(actor_update_interval=0)


def _parameters(part):
    return list(part.parameters()) if hasattr(part, "parameters") else list(part)


def test_augment_is_refused_where_it_cannot_apply(tmp_path):
    from visualenv.env.registration import resolve
    from visualenv.spec import load_spec
    from visualenv.train.drq import check_augment

    loaded = load_spec(resolve("LunarLanding-v0"))
    out = tmp_path / "runs"
    result = CliRunner().invoke(
        main, ["train", "LunarLanding-v0", "--algo", "sac", "--state-only", "--augment", "shift", "--out", str(out)]
    )
    assert result.exit_code != 0 and "--augment shift" in result.output and "state-only" in result.output
    assert "Traceback" not in result.output and not out.exists()
    with pytest.raises(ConfigError, match="--augment shift: for --algo ppo or sac, not dqn"):
        check_augment("shift", "dqn", True, loaded)
    check_augment("shift", "sac", True, loaded)  # one camera: fine
    check_augment(None, "dqn", False, loaded)
    assert model_arguments("ppo", None, "CnnPolicy") == ("CnnPolicy", {})
    result = CliRunner().invoke(main, ["train", "LunarLanding-v0", "--augment", "flip"])
    assert result.exit_code != 0 and "--augment" in result.output


def test_a_config_without_augment_reads_as_none(tmp_path):
    from dataclasses import asdict

    from visualenv.train.run_folder import read_config, write_config
    from visualenv.train.sb3 import TrainConfig, resumed_config

    settings = asdict(TrainConfig("LunarLanding-v0", algo="sac", augment="shift"))
    write_config(tmp_path, {"backend": "sb3", "command": "visualenv train", "config": settings})
    assert read_config(tmp_path)["config"]["augment"] == "shift"
    record = json.loads((tmp_path / "config.json").read_text())
    del record["config"]["augment"]  # a run (or shipped agent) from before --augment
    (tmp_path / "config.json").write_text(json.dumps(record))
    assert read_config(tmp_path)["config"]["augment"] is None
    assert resumed_config(TrainConfig, tmp_path, steps=None, hyperparams={}, progress=False).augment is None
    record["config"]["augment"] = "crop"
    (tmp_path / "config.json").write_text(json.dumps(record))
    with pytest.raises(ConfigError, match="augment: expected one of shift"):
        read_config(tmp_path)


def test_the_refusal_of_a_buffer_too_big_names_a_size_that_fits(tmp_path):
    from visualenv.env.registration import resolve
    from visualenv.spec import load_spec
    from visualenv.train.config_checks import STORED_MEMORY_SHARE, check_replay_buffer, replay_buffer_bytes
    from visualenv.train.sb3 import TrainConfig

    import psutil
    import re

    loaded = load_spec(resolve("LunarLanding-v0"))
    config = TrainConfig("LunarLanding-v0", algo="sac", augment="shift")
    one = replay_buffer_bytes(config, {"buffer_size": 1}, loaded)
    assert one == 4 * 100 * 100  # 4 stacked grayscale frames, once
    huge = 10 * int(psutil.virtual_memory().total // one)
    with pytest.raises(ConfigError) as refused:
        check_replay_buffer(config, {"buffer_size": huge}, loaded)
    fits = int(re.search(r"set buffer_size=([\d,]+) or less", str(refused.value)).group(1).replace(",", ""))
    assert 0 < fits * one <= STORED_MEMORY_SHARE * psutil.virtual_memory().total
    check_replay_buffer(config, {"buffer_size": fits // 2}, loaded)


def test_a_sac_target_interval_that_sb3_would_not_keep_is_warned_of_with_the_tau_that_would(recwarn):
    """SB3's SAC moves its target at gradient steps 0, k, 2k... of each update call: with one update a call an interval
    of 2 moves it every update. `train` says so before any env starts, and says nothing where the interval holds."""
    import warnings

    from visualenv.train.config_checks import check_target_pace
    from visualenv.train.sb3 import TrainConfig

    def warned(algo: str = "sac", envs: int = 1, **kwargs) -> list[str]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_target_pace(TrainConfig(spec="DMC-cartpole-swingup-v0", algo=algo, envs=envs), kwargs)
        return [str(w.message) for w in caught]

    message = warned(target_update_interval=2, tau=0.01, gradient_steps=-1, train_freq=1)
    assert len(message) == 1 and "counts updates within each update call (SB3 issue 2158)" in message[0]
    assert "moves 1 time(s) in each call's 1 update(s), not once every 2" in message[0] and "tau=0.005" in message[0]
    assert "moves 2 time(s) in each call's 3 update(s)" in warned(target_update_interval=2, gradient_steps=3)[0]
    assert (
        "call's 2 update(s), not once every 4"
        in warned(target_update_interval=4, gradient_steps=-1, train_freq=(1, "step"), envs=2)[0]
    )
    assert warned(target_update_interval=2, gradient_steps=4) == []  # a multiple: the pace holds
    assert warned(target_update_interval=1) == [] and warned("td3", target_update_interval=2) == []
    assert warned(target_update_interval=2, train_freq=(1, "episode")) == []  # a call's updates vary: not judged
    drq = TrainConfig(spec="DMC-cartpole-swingup-v0", algo="sac", augment="shift")
    with warnings.catch_warnings(record=True) as caught:  # DrQ's SAC counts across calls: its interval holds
        warnings.simplefilter("always")
        check_target_pace(drq, {"target_update_interval": 2, "gradient_steps": -1})
    assert caught == []


def test_the_dmc_preset_builds_drqs_sac():
    """examples/hyperparams/dmc_drq.yaml: SAC's hyperparameters, checked as `train --config` checks them."""
    from pathlib import Path

    import yaml

    from visualenv.train.sb3 import algorithm_kwargs

    preset = yaml.safe_load((Path(__file__).parents[2] / "examples/hyperparams/dmc_drq.yaml").read_text())
    kwargs = algorithm_kwargs("sac", {**preset, "buffer_size": 100}, "shift")  # the preset's 100k frames: 5.9 GiB
    assert preset["buffer_size"] == 100_000 and preset["ent_coef"] == "auto_0.1"
    assert preset["tau"] == 0.01 and preset["target_update_interval"] == 2 and preset["actor_update_interval"] == 2
    with pytest.raises(
        ConfigError, match="actor_update_interval is a hyperparameter of DrQ's SAC: train with --augment"
    ):
        algorithm_kwargs("sac", preset)  # without --augment: SB3's SAC, which has no actor delay

    class Pixels(_Frames):
        observation_space = spaces.Box(0, 255, (84, 84, 9), np.uint8)  # 3 stacked RGB frames

    policy, extra = model_arguments("sac", "shift", "CnnPolicy")
    model = DrQSAC(policy, Pixels(), seed=0, device="cpu", **kwargs, **extra)
    assert model.actor_update_interval == 2 and model.target_update_interval == 2
    assert model.policy.actor.features_extractor.features_dim == 50
    assert [layer.out_features for layer in model.policy.critic.q_networks[0] if hasattr(layer, "out_features")] == [
        1024,
        1024,
        1,
    ]


def test_a_resumed_model_keeps_drqs_policy_and_buffers(tmp_path):
    """`train --resume` loads checkpoints/latest.zip with the algorithm's class: DrQ's classes come back with it."""
    from stable_baselines3 import PPO

    policy, extra = model_arguments("sac", "shift", "CnnPolicy")
    DrQSAC(policy, _Frames(), buffer_size=32, device="cpu", actor_update_interval=2, **extra).save(tmp_path / "sac.zip")
    back = algorithm_class("sac", "shift").load(tmp_path / "sac.zip", env=_Frames(), device="cpu")
    assert isinstance(back, DrQSAC) and back.actor_update_interval == 2
    assert isinstance(back.policy, DrQSACPolicy) and isinstance(back.replay_buffer, DrQReplayBuffer)
    policy, extra = model_arguments("ppo", "shift", "CnnPolicy")
    PPO(policy, _Frames(), n_steps=8, batch_size=8, device="cpu", **extra).save(tmp_path / "ppo.zip")
    assert isinstance(PPO.load(tmp_path / "ppo.zip", env=_Frames(), device="cpu").rollout_buffer, ShiftedRolloutBuffer)


def test_a_checkpoint_keeps_the_final_frames_of_timeouts(tmp_path):
    """`train --resume`'s data checkpoint (visualenv.train.checkpoints) saves the frames the buffer keeps aside."""
    from visualenv.train.checkpoints import CheckpointError, load_state, save_state
    from visualenv.train.run_folder import STATE_REPLAY, RunFolder

    def make():
        policy, extra = model_arguments("sac", "shift", "CnnPolicy")
        env = gym.wrappers.TimeLimit(_Frames(), 3)  # every episode cut by its time limit
        return DrQSAC(policy, env, buffer_size=32, learning_starts=32, seed=0, device="cpu", **extra)

    trained = make()
    trained.learn(12)
    kept = trained.replay_buffer.kept_arrays()
    assert len(kept["final_slots"]) == 4 and kept["final_slots"][:, 0].tolist() == [2, 5, 8, 11]
    folder = RunFolder(tmp_path)
    save_state(trained, folder, "sac")
    resumed = make()
    load_state(resumed, folder.latest_dir, "sac")
    back = resumed.replay_buffer.kept_arrays()
    assert all(np.array_equal(kept[k], back[k]) for k in kept)
    assert np.array_equal(resumed.replay_buffer.has_final, trained.replay_buffer.has_final)
    assert np.array_equal(resumed.replay_buffer.observations, trained.replay_buffer.observations)

    saved = dict(np.load(folder.latest_dir / STATE_REPLAY))  # a slot past the buffer's end is refused
    np.savez(folder.latest_dir / STATE_REPLAY, **{**saved, "final_slots": saved["final_slots"] + [40, 0]})
    with pytest.raises(CheckpointError, match="final_slots: a slot outside the buffer"):
        load_state(make(), folder.latest_dir, "sac")
    frames = np.zeros((100, 3, 40, 40), np.uint8)  # more frames than the buffer has slots: refused unread
    np.savez(
        folder.latest_dir / STATE_REPLAY,
        **{**saved, "final_observations": frames, "final_slots": np.zeros((100, 2), np.int64)},
    )
    with pytest.raises(CheckpointError, match="expected at most 32 frames"):
        load_state(make(), folder.latest_dir, "sac")


def test_a_config_names_drqs_encoder_and_a_policy_file_rebuilds_it(tmp_path):
    """``policy_kwargs: {features_extractor_class: visualenv.train.encoders.DrQEncoder}``: DrQ's own encoder (four 3x3
    convolutions, the first of stride 2; linear, LayerNorm, tanh), shared as DrQ shares it, named in the policy file."""
    from stable_baselines3 import SAC

    from visualenv.train.encoders import DrQEncoder
    from visualenv.train.model_files import load_model, save_policy
    from visualenv.train.policy_format import read_meta
    from visualenv.train.sb3 import algorithm_kwargs

    name = "visualenv.train.encoders.DrQEncoder"
    kwargs = algorithm_kwargs(
        "sac", {"policy_kwargs": {"features_extractor_class": name, "features_extractor_kwargs": {"features_dim": 50}}}
    )
    policy, extra = model_arguments("sac", "shift", "CnnPolicy")
    model = SAC(
        policy, _Frames(), buffer_size=64, learning_starts=8, batch_size=8, seed=0, device="cpu", **kwargs, **extra
    )
    model.learn(12)  # a few updates through it
    encoder = model.policy.actor.features_extractor
    critic = model.policy.critic.features_extractor
    assert isinstance(encoder, DrQEncoder) and isinstance(critic, DrQEncoder)
    assert critic.convolutions is encoder.convolutions and critic.head is not encoder.head  # DrQ's sharing
    convolutions = [layer for layer in encoder.convolutions if isinstance(layer, torch.nn.Conv2d)]
    assert [(c.out_channels, c.kernel_size, c.stride) for c in convolutions] == [(32, (3, 3), (2, 2))] + 3 * [
        (32, (3, 3), (1, 1))
    ]
    assert encoder.head[0].in_features == 32 * 13 * 13  # 40x40: 19x19 after the stride 2, 13x13 after three more
    features = encoder(torch.rand(5, 3, 40, 40) * 100)
    assert features.shape == (5, 50) and features.abs().max() < 1  # tanh

    # DrQ's initialisation: only each convolution's centre tap is set, orthogonal columns of norm sqrt(2)
    fresh = DrQEncoder(spaces.Box(0, 255, (9, 84, 84), np.uint8))
    for conv in [layer for layer in fresh.convolutions if isinstance(layer, torch.nn.Conv2d)]:
        weight = conv.weight.detach()
        centre, others = weight[:, :, 1, 1], weight.clone()
        others[:, :, 1, 1] = 0
        assert not others.any() and not conv.bias.any()
        assert torch.allclose(centre.T @ centre, 2 * torch.eye(centre.shape[1]), atol=1e-5)

    # a policy file names it, and reading the file back (checked on torch's meta device first) rebuilds it
    save_policy(model, tmp_path / "policy.safetensors", half=False)
    meta = read_meta(tmp_path / "policy.safetensors")
    assert (
        meta["arguments"]["features_extractor_class"] == name and meta["policy"] == "visualenv.train.drq.DrQSACPolicy"
    )
    rebuilt = load_model(tmp_path / "policy.json")
    frame = torch.rand(2, 3, 40, 40)
    assert isinstance(rebuilt.actor.features_extractor, DrQEncoder)
    assert torch.equal(rebuilt.actor.features_extractor(frame), encoder(frame))

    with pytest.raises(ConfigError, match="policy_kwargs.features_extractor_class 'DrQ' is not one visualenv builds; "):
        algorithm_kwargs("sac", {"policy_kwargs": {"features_extractor_class": "DrQ"}})
    out = tmp_path / "runs"
    args = ["train", "LunarLanding-v0", "--algo", "sac", "--augment", "shift", "--out", str(out), "--set"]
    result = CliRunner().invoke(main, [*args, 'policy_kwargs={"features_extractor_class": "DrQ"}'])
    assert result.exit_code != 0 and "allowed: stable_baselines3.common.torch_layers.NatureCNN" in result.output
    assert name in result.output and "Traceback" not in result.output and not out.exists()
    with pytest.raises(ConfigError, match="needs images of at least 15x15"):
        DrQEncoder(spaces.Box(0, 255, (3, 12, 12), np.uint8))
