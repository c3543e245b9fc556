"""`visualenv distill`: a pixel policy taught by a state-only one (DAgger), the short way to a pixel agent on a few cores.

Reinforcement learning from pixels spends most of its samples and updates learning to
see. A state-only agent of the same env trains in minutes (``visualenv train --state-only``);
distillation then teaches a CNN policy to act as that teacher does, from the frames alone.
It runs DAgger (Ross, Gordon and Bagnell, 2011): in round 0 the teacher acts; in round r
it acts a step with probability mixing ** r, else the student does (DAgger's beta). The
teacher labels every state visited with its own action, and after each round the student
fits every label gathered so far (the squared error of its deterministic action, or the
cross-entropy of a discrete one) on frames shifted at random by a few pixels (DrQ's augmentation),
and, if asked, turned and scaled at random as a camera's roll and zoom would; with distracted
frames, its features may also be drawn to those of the same states rendered clean (``consistency``).

The student is SB3's ``ActorCriticCnnPolicy`` (NatureCNN, or DrQ's encoder) on the stacked frames, so it
ships, loads and evaluates like a PPO agent: ``visualenv eval``, ``play``, the policy file.
Its value head is untrained. A distilled agent's returns are not reinforcement learning's
returns at so many env steps: docs/distill.md says how to report them.

A run folder ``runs/<Id>/<timestamp>/`` holds ``config.json`` (command, settings, versions,
the teacher's file and sha256), ``rounds.csv`` (per round: frames, the rollouts' mean return,
the loss, the selection evaluation), ``best_model.safetensors`` (the round that evaluated
best), ``final_model.safetensors`` and ``results.json`` (the best model on fresh seeds).
"""

from __future__ import annotations

import csv
import hashlib
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from visualenv.compat import mkl
from visualenv.errors import ConfigError
from visualenv.train.run_folder import RunFolder, new_run_dir, record_run, write_results
from visualenv.train.stopping import StopRequest

ROUNDS_COLUMNS = ("round", "frames", "rollout_return", "loss", "eval_return", "wall_s")
#: the student's image encoders (`--encoder`): SB3's NatureCNN, DrQ's (:class:`visualenv.train.encoders.DrQEncoder`)
STUDENT_ENCODERS = ("nature", "drq")


@dataclass
class DistillConfig:
    """The settings of a distillation, as `visualenv distill`'s options name them (config.json records them)."""

    spec: str
    teacher: str  # a state-only policy file of the same spec (`visualenv train --state-only`)
    rounds: int = 8  # DAgger rounds; round 0 is the teacher's own unless a student is given
    episodes: int = 16  # episodes rolled out per round
    # the teacher acts a step of round r with probability mixing ** r (DAgger's beta), else the student
    mixing: float = 0.5
    # a policy file of an earlier distillation of the spec to start from (then mixing ** (r + 1))
    student: str | None = None
    epochs: float = 2.0  # passes over all frames gathered so far, per round
    batch_size: int = 128
    learning_rate: float = 3e-4
    shift: int = 4  # random shift of the frames in pixels (0: none)
    # each training image turned by up to `rotate` degrees and scaled by up to `zoom` either way (a camera's roll and
    # zoom, which distractions' camera applies at evaluation), after the shift (0, 0: none)
    rotate: float = 0.0
    zoom: float = 0.0
    # weight of an auxiliary loss: a linear head on the student's CNN features predicts the teacher's state vector
    # (standardised), so the encoder learns from the whole state, not only the action; the head is not saved (0: none)
    state_loss: float = 0.0
    # weight of a loss drawing together the student's features of each distracted frame and of the same state
    # rendered without distractions (by a twin env stepped with the same actions), which it fits too (SODA's idea:
    # features that the distractions do not move); needs `distractions` (0: none, and no twin)
    consistency: float = 0.0
    # the student's image encoder: SB3's NatureCNN ('nature'), or DrQ's ('drq': four 3x3 convolutions, 50 features;
    # visualenv.train.encoders.DrQEncoder), which does several times NatureCNN's arithmetic per frame
    encoder: str = "nature"
    frame_stack: int = 3
    # the rounds' frames distracted (docs/distractions.md): a difficulty, [low, high] drawn per episode, or a spec's
    # distractions section (e.g. with DAVIS videos as the background); the final
    # evaluation stays undistracted, as results.json is everywhere
    distractions: float | list[float] | dict[str, Any] | None = None
    eval_episodes: int = 10  # per round, on the selection seeds
    final_eval_episodes: int = 100
    seed: int = 0
    progress: bool = True


def distill(
    config: DistillConfig, out_root: str | Path, *, log: Callable[[str], None] = print, trust_code: bool = False
) -> tuple[Path, dict[str, Any]]:
    """Run DAgger rounds, keep the round that evaluates best, evaluate it on fresh seeds: the run folder made under
    `out_root` once the teacher and the student are checked, and results.json's figures. `trust_code`: the spec's
    ``dynamics.python`` may be imported (docs/security.md)."""
    import torch

    from visualenv.env.registration import resolve
    from visualenv.spec.loader import load_spec
    from visualenv.train.evaluation import final_evaluation, final_seed, make_eval_env, selection_seed
    from visualenv.train.model_files import load_model, load_policy_file, save_policy

    spec_path = str(resolve(config.spec))
    if config.consistency > 0 and config.distractions is None:
        raise ConfigError("--consistency compares distracted frames with clean ones: give --distractions too")
    mkl.pin()  # before the student is built, as `visualenv eval` does: its final evaluation replays there
    teacher = load_policy_file(config.teacher, "distill")
    _check_teacher(teacher, spec_path, trust_code)
    torch.manual_seed(config.seed)
    options: dict[str, Any] = {"frame_stack": config.frame_stack, "trust_code": trust_code}
    if config.distractions is not None:
        options["distractions"] = config.distractions
    rollouts = make_eval_env(spec_path, seed=config.seed, **options)
    evaluator = make_eval_env(spec_path, seed=selection_seed(config.seed), **options)
    # the rollouts' states again without distractions: the same seed and actions give the same physics
    twin = None
    if config.consistency > 0:
        twin = make_eval_env(spec_path, seed=config.seed, frame_stack=config.frame_stack, trust_code=trust_code)
    try:
        log(f"the rounds keep {_check_frame_memory(config, rollouts)}")
        start = load_policy_file(config.student, "distill") if config.student else None
        student = _student(rollouts, start, config.encoder)
        run_dir = new_run_dir(out_root, load_spec(spec_path).spec.id)
        folder = RunFolder(run_dir)
        log(f"run folder: {run_dir}")
        _record_run(folder, config, spec_path)
        started = time.perf_counter()
        with StopRequest("this round").listening() as stop:
            best_score, frames = _rounds(student, teacher, rollouts, evaluator, config, folder, log, stop, twin)
        student.to(memory_format=torch.contiguous_format)  # safetensors stores contiguous tensors
        save_policy(student, folder.final_policy, half=False, algorithm="dagger", run_dir=run_dir)
        best_path = folder.best_policy
        wall = time.perf_counter() - started  # the rounds' time, without the final evaluation, as train's
    finally:
        for env in (rollouts, evaluator, twin):
            if env is not None:
                env.close()
    final_env = make_eval_env(
        spec_path, seed=final_seed(config.seed), frame_stack=config.frame_stack, trust_code=trust_code
    )
    try:
        results = final_evaluation(
            load_model(best_path), final_env, config.final_eval_episodes, final_seed(config.seed)
        )
    finally:
        final_env.close()
    results.update(
        {
            "selection": {
                "eval_seed": selection_seed(config.seed),
                "mean_reward": best_score,
                "episodes": config.eval_episodes,
            },
            "frames": frames,
            "wall_time_s": round(wall, 1),
            "model": best_path.name,
        }
    )
    write_results(folder, results)
    return run_dir, results


def _rounds(
    student: Any,
    teacher: Any,
    rollouts: Any,
    evaluator: Any,
    config: DistillConfig,
    folder: RunFolder,
    log: Callable[[str], None],
    stop: StopRequest,
    twin: Any = None,
) -> tuple[float, int]:
    """The DAgger rounds, each a row of rounds.csv, until the last or a stop request: the best evaluation and the
    frames. The best round's student is saved as it evaluates, so a stopped or killed run keeps it. `twin`: the
    rollouts' env without distractions, whose frames the consistency loss compares."""
    import torch

    from visualenv.train.evaluation import evaluate
    from visualenv.train.model_files import save_policy

    state_size = int(np.prod(teacher.observation_space.shape))
    probe = _StateProbe(student, state_size) if config.state_loss > 0 else None
    parameters = [*student.parameters(), *(probe.head.parameters() if probe else ())]
    optimizer = torch.optim.Adam(parameters, lr=config.learning_rate)
    generator = np.random.default_rng(config.seed)
    frames, cleans = _Rows(), _Rows()
    labels: list[np.ndarray] = []
    states: list[np.ndarray] = []
    best = -np.inf
    started = time.perf_counter()
    with folder.rounds.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(ROUNDS_COLUMNS)
        for round_ in range(config.rounds):
            share = config.mixing ** (round_ + bool(config.student))  # a given student acts from the first round on
            with _episode_bar(config, round_) as bar:
                obs, act, state, returns, clean = _rollouts(
                    rollouts, teacher, student, share, config.episodes, generator, bar, twin
                )
            frames.append(obs)
            labels.append(act)
            states.append(state)
            if clean is not None:
                cleans.append(clean)
            gathered = frames, np.concatenate(labels), np.concatenate(states)
            loss = _fit(student, optimizer, gathered, config, generator, probe, cleans if len(cleans) else None)
            scored = evaluate(student, evaluator, config.eval_episodes)["mean_reward"]
            if scored > best:
                best = scored
                student.to(memory_format=torch.contiguous_format)  # safetensors stores contiguous tensors
                save_policy(student, folder.best_policy, half=False, algorithm="dagger", run_dir=folder.path)
            row = (
                round_,
                len(frames),
                round(float(np.mean(returns)), 3),
                round(loss, 6),
                round(scored, 3),
                round(time.perf_counter() - started, 1),
            )
            writer.writerow(row)
            f.flush()
            log(  # with or without the bar, as train's line per evaluation: a run's log shows its rounds
                f"round {round_}: {row[1]} frames, rollouts {row[2]:.1f} (the teacher's share {share:.0%}), "
                f"loss {loss:.4f}, evaluation {scored:.1f}"
            )
            if stop.requested:
                break
    return best, len(frames)


def _record_run(folder: RunFolder, config: DistillConfig, spec_path: str) -> None:
    """config.json: the command, the settings under the keys `eval` and `export-policy` read, the versions, and the
    teacher's file and the student's it started from (path and sha256)."""

    def named(path: str) -> dict[str, str]:
        return {"path": path, "sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest()}

    extra = {"teacher": named(config.teacher), **({"student": named(config.student)} if config.student else {})}
    settings = {**asdict(config), "algo": "dagger", "render": True}
    if isinstance(config.distractions, (int, float)):
        settings["distractions"] = [config.distractions]  # recorded as a list: [difficulty] or [low, high]
    record_run(folder, settings, spec_path, backend="distill", extra=extra)


def _check_teacher(teacher: Any, spec_path: str, trust_code: bool = False) -> None:
    """A teacher that cannot read this env's state, or acts in another action space, is a clear error before anything runs."""
    from visualenv.env import VisualEnv
    from visualenv.spec import load_spec

    env = VisualEnv(load_spec(spec_path), render=False, trust_code=trust_code)
    try:
        state, actions = env.observation_space, env.action_space
    finally:
        env.close()
    if teacher.observation_space.shape != state.shape or teacher.action_space != actions:
        raise ConfigError(
            f"the teacher acts on observations of shape {teacher.observation_space.shape} with actions {teacher.action_space}; "
            f"{spec_path}'s state-only observations have shape {state.shape} and its actions are {actions}: "
            "train the teacher on the same spec with `visualenv train --state-only`"
        )


def _student(vec_env: Any, start: Any = None, encoder: str = "nature") -> Any:
    """SB3's PPO CNN policy on the env's stacked, channels-first frames, its frames read by `encoder` (`start`'s
    weights: a policy of the same spaces and encoder), laid out channels last: oneDNN's convolutions on a CPU fit it
    more than twice as fast so (results/benchmarks/code-choices.md)."""
    from stable_baselines3.common.policies import ActorCriticCnnPolicy
    from stable_baselines3.common.torch_layers import NatureCNN

    from visualenv.train.encoders import DrQEncoder, channels_last

    extractor = dict(zip(STUDENT_ENCODERS, (NatureCNN, DrQEncoder)))[encoder]
    student = ActorCriticCnnPolicy(
        vec_env.observation_space, vec_env.action_space, lambda _: 0.0, features_extractor_class=extractor
    )
    if start is not None:
        if start.observation_space != vec_env.observation_space or start.action_space != vec_env.action_space:
            raise ConfigError(
                f"the student to start from sees {start.observation_space} and acts in {start.action_space}; "
                f"this env's stacked frames are {vec_env.observation_space} and its actions {vec_env.action_space}"
            )
        if type(start.features_extractor) is not extractor:
            raise ConfigError(
                f"the student to start from encodes its frames with {type(start.features_extractor).__name__}; "
                f"--encoder {encoder} is {extractor.__name__}: give --encoder as its run did (its config.json)"
            )
        student.load_state_dict(start.state_dict())
    return channels_last(student)


def _episode_bar(config: DistillConfig, round_: int) -> Any:
    """A tqdm bar over a round's rollout episodes (a round takes minutes), off with `progress` off."""
    from tqdm import tqdm

    return tqdm(total=config.episodes, desc=f"round {round_}", unit="episode", leave=False, disable=not config.progress)


def _check_frame_memory(config: DistillConfig, rollouts: Any) -> str:
    """The most memory the rounds' frames can take, in words; refused before the run starts where it exceeds the
    available memory's share (:func:`~visualenv.train.config_checks.memory_room`, as a replay buffer's): DAgger keeps
    every frame of every round, so a run of many episodes a round would otherwise fail hours in."""
    from visualenv.train.config_checks import memory_room

    steps = rollouts.unwrapped.envs[0].unwrapped.max_episode_steps
    views = 2 if config.consistency > 0 else 1  # the distracted frame and its clean twin
    per_frame = int(np.prod(rollouts.observation_space.shape)) * rollouts.observation_space.dtype.itemsize * views
    rows = config.rounds * config.episodes * steps
    need, (room, available) = rows * per_frame, memory_room()
    if need > room:
        fits = int(room // (config.rounds * steps * per_frame))
        raise ConfigError(
            f"{config.rounds} rounds of {config.episodes} episodes of up to {steps} steps would keep "
            f"{need / 2**30:.1f} GiB of frames, and {available / 2**30:.1f} GiB of memory are available: "
            + (f"set --episodes {fits} or less, or fewer --rounds" if fits else "set fewer --rounds")
        )
    return f"at most {rows:,} frames ({need / 2**30:.1f} GiB)"


class _Rows:
    """Arrays of rows gathered round by round, read as if concatenated but never copied into one: a run's frames are
    most of its memory, and a copy each round would double it."""

    def __init__(self) -> None:
        self.parts: list[np.ndarray] = []
        self.starts = np.zeros(1, dtype=np.int64)  # each part's first row, then the number of rows

    def append(self, part: np.ndarray) -> None:
        self.parts.append(part)
        self.starts = np.append(self.starts, self.starts[-1] + len(part))

    def __len__(self) -> int:
        return int(self.starts[-1])

    @property
    def shape(self) -> tuple[int, ...]:
        return (len(self), *self.parts[0].shape[1:])

    def __getitem__(self, rows: np.ndarray) -> np.ndarray:
        """The `rows` (indices into all rows) in their order, as one array."""
        part = np.searchsorted(self.starts, rows, side="right") - 1
        out = np.empty((len(rows), *self.parts[0].shape[1:]), dtype=self.parts[0].dtype)
        for k in np.unique(part):
            where = part == k
            out[where] = self.parts[k][rows[where] - self.starts[k]]
        return out


def _rollouts(
    vec_env: Any,
    teacher: Any,
    student: Any,
    teacher_share: float,
    episodes: int,
    generator: np.random.Generator,
    bar: Any = None,
    twin: Any = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[float], np.ndarray | None]:
    """`episodes` episodes, each step acted by the teacher with probability `teacher_share`, else by the student:
    each frame, the teacher's action, the state it saw and (given a `twin` env) the twin's frame of that state, the
    twin stepping through each episode's actions once it ends (envs of one process that render in turn each step
    cost several times more). `bar` (a tqdm bar) advances by one per episode."""
    env = vec_env.unwrapped.envs[0].unwrapped
    discrete = getattr(env.action_space, "n", None)
    frames: list[np.ndarray] = []
    labels: list[np.ndarray] = []
    states: list[np.ndarray] = []
    returns: list[float] = []
    cleans: list[np.ndarray] = []
    obs = vec_env.reset()
    clean: Any = twin.reset() if twin is not None else None
    actions: list[np.ndarray] = []  # the episode's, for the twin
    ret = 0.0
    while len(returns) < episodes:
        state = np.asarray(env.state_observation(), dtype=np.float32)
        label, _ = teacher.predict(state[None], deterministic=True)
        states.append(state.ravel())
        frames.append(obs[0])
        labels.append(np.asarray(label[0], dtype=np.float32 if discrete is None else np.int64))
        action = label if generator.random() < teacher_share else student.predict(obs, deterministic=True)[0]
        actions.append(action)
        obs, reward, done, _ = vec_env.step(action)
        ret += float(reward[0])
        if done[0]:
            returns.append(ret)
            ret = 0.0
            if twin is not None:
                clean = _replay(twin, clean, actions, states[-len(actions) :], cleans)
            actions = []
            if bar is not None:
                bar.update(1)
    return np.stack(frames), np.stack(labels), np.stack(states), returns, np.stack(cleans) if cleans else None


def _replay(twin: Any, first: Any, actions: list[np.ndarray], states: list[np.ndarray], cleans: list) -> Any:
    """An episode's `actions` stepped in the `twin` env from its observation `first`, each frame appended to `cleans`
    once the twin's state is checked to be the episode's (`states`): the twin's next observation.

    Distractions draw from their own generator, so the same seed and actions give the same physics; a spec whose
    dynamics differ with them would break that, and is refused."""
    env = twin.unwrapped.envs[0].unwrapped
    clean = first
    for action, state in zip(actions, states):
        if not np.array_equal(np.asarray(env.state_observation(), dtype=np.float32).ravel(), state):
            raise ConfigError(
                "--consistency needs the env's states to follow from its seed and actions alone, but the "
                "undistracted twin's state left the distracted env's: this spec's dynamics differ with its distractions"
            )
        cleans.append(clean[0])
        clean = twin.step(action)[0]
    return clean


class _FeatureTap:
    """The student's features as its last forward pass computed them (a forward hook on its extractor, removed on
    leaving), for the losses on them: the state probe's and the consistency loss."""

    def __init__(self, student: Any):
        self.extractor = student.features_extractor
        self.output: Any = None

    def __enter__(self) -> "_FeatureTap":
        self._hook = self.extractor.register_forward_hook(
            lambda module, inputs, output: setattr(self, "output", output)
        )
        return self

    def __exit__(self, *exc: object) -> None:
        self._hook.remove()
        self.output = None


class _StateProbe:
    """A linear head on the student's CNN features that predicts the teacher's state: an action is one number or a
    few, the state is all the frames hold for the task."""

    def __init__(self, student: Any, state_size: int):
        import torch

        self.head = torch.nn.Linear(student.features_extractor.features_dim, state_size)

    def loss(self, features: Any, states: np.ndarray, mean: np.ndarray, scale: np.ndarray) -> Any:
        """The squared error of the prediction of `states` from `features`, each standardised by `mean` and `scale`."""
        import torch

        return torch.nn.functional.mse_loss(self.head(features), torch.from_numpy((states - mean) / scale))


def _fit(
    student: Any,
    optimizer: Any,
    gathered: tuple[_Rows | np.ndarray, np.ndarray, np.ndarray],
    config: DistillConfig,
    generator: np.random.Generator,
    probe: _StateProbe | None = None,
    clean: _Rows | np.ndarray | None = None,
) -> float:
    """`config.epochs` passes of minibatches over every frame, label and state so far (the loss: the imitation loss,
    plus `config.state_loss` times the probe's; given `clean` twins of the frames, those too are fitted, and
    `config.consistency` times the squared distance between each frame's features and its twin's is added); the last
    pass's mean imitation loss."""
    import torch

    frames, labels, states = gathered
    mean, scale = states.mean(axis=0), np.maximum(states.std(axis=0), 1e-6).astype(np.float32)
    student.set_training_mode(True)
    updates = max(1, int(config.epochs * len(frames) / config.batch_size))
    losses = []
    with _FeatureTap(student) as features:
        for _ in range(updates):
            batch = generator.integers(0, len(frames), config.batch_size)
            images = torch.from_numpy(frames[batch])
            if clean is not None:  # both views shifted and warped alike: stacked as one image's channels
                images = torch.cat([images, torch.from_numpy(clean[batch])], dim=1)
            images = _warped(_shifted(images, config.shift, generator), config.rotate, config.zoom, generator)
            parts = images.split(frames.shape[1], dim=1)  # then one batch: the distracted views, the clean ones
            views, images = len(parts), torch.cat(parts).contiguous(memory_format=torch.channels_last)
            distribution = student.get_distribution(images).distribution
            imitation = _imitation_loss(distribution, torch.from_numpy(np.concatenate([labels[batch]] * views)))
            loss = imitation
            if probe is not None:
                seen = np.concatenate([states[batch]] * views)
                loss = loss + config.state_loss * probe.loss(features.output, seen, mean, scale)
            if views == 2:  # both ways: a target held fixed chases the features it moves
                distracted, undistracted = features.output.chunk(2)
                loss = loss + config.consistency * torch.nn.functional.mse_loss(distracted, undistracted)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            losses.append(imitation.item())
    student.set_training_mode(False)
    last = losses[-max(1, len(frames) // config.batch_size) :]
    return float(np.mean(last))


def _imitation_loss(distribution: Any, labels: Any) -> Any:
    """How far the student's deterministic action is from the teacher's: squared error of the Gaussian's mean to a
    continuous action, cross-entropy of the logits to a discrete one."""
    import torch

    if isinstance(distribution, torch.distributions.Categorical):
        return torch.nn.functional.cross_entropy(distribution.logits, labels.long())
    return torch.nn.functional.mse_loss(distribution.mean, labels)


def _shifted(images: Any, shift: int, generator: np.random.Generator) -> Any:
    """Each image moved by up to `shift` pixels each way, its edge pixels repeated (DrQ's random shift), the offsets
    drawn from the run's `generator`."""
    from visualenv.train.drq import crop_padded

    if shift == 0:
        return images
    dy, dx = generator.integers(0, 2 * shift + 1, (2, images.shape[0]))
    return crop_padded(images, shift, dy.tolist(), dx.tolist())


def _warped(images: Any, rotate: float, zoom: float, generator: np.random.Generator) -> Any:
    """Each (C, H, W) image turned about its centre by an angle drawn in [-rotate, rotate] degrees and scaled by a
    factor drawn in [1 - zoom, 1 + zoom] (above 1 its content shrinks, as a camera zooming out), all its stacked
    frames alike, its edge pixels repeated; float pixels on the images' scale. The draws come from the run's
    `generator`."""
    import torch
    import torch.nn.functional as F

    if rotate == 0 and zoom == 0:
        return images
    n, _, height, width = images.shape
    angles = np.radians(generator.uniform(-rotate, rotate, n))
    scales = generator.uniform(1 - zoom, 1 + zoom, n)
    cos, sin = torch.from_numpy(scales * np.cos(angles)).float(), torch.from_numpy(scales * np.sin(angles)).float()
    # an output pixel's normalised coordinates mapped to the input's (the map F.affine_grid builds, written out by
    # broadcasting, which costs the CPU less); the aspect terms keep the turn rigid in pixels
    xs = ((torch.arange(width, dtype=torch.float32) * 2 + 1) / width - 1).view(1, 1, width)
    ys = ((torch.arange(height, dtype=torch.float32) * 2 + 1) / height - 1).view(1, height, 1)
    cos, sin = cos.view(n, 1, 1), sin.view(n, 1, 1)
    grid = torch.stack([cos * xs - sin * (height / width) * ys, sin * (width / height) * xs + cos * ys], dim=-1)
    return F.grid_sample(images.float(), grid, mode="bilinear", padding_mode="border", align_corners=False)
