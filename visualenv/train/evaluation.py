"""Deterministic evaluation of a trained agent: `visualenv train`'s final evaluation and `visualenv eval`.

Both run :func:`final_evaluation` on the env :func:`make_eval_env` makes, so
``visualenv eval`` with the seed a run recorded (``eval_seed`` in results.json)
plays the same episodes and prints the same numbers as the run's results.json.

Seeds come in bands that never meet, so the figure a run reports is measured on
episodes that neither trained nor picked its model (picking the best of many close
evaluations biases the winner's score upward). A run seeded ``s`` (below
:data:`~visualenv.train.run_settings.MAX_TRAIN_SEED`) trains on ``s, s+1, ...``, picks its best model on the stream
:func:`selection_seed` ``(s)`` and reports :func:`final_seed` ``(s)``; ``visualenv eval``
of a model without a run plays :data:`FRESH_SEED`.

Intervals are 95 %: a percentile bootstrap of the mean (10,000 resamples, a fixed
resampling seed, so the same episodes give the same interval) for the return and
the length, and the Wilson score interval for the success rate (sound near 0 and 1,
where the normal approximation leaves [0, 1]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from visualenv.compat import mkl
from visualenv.env.wrappers import FrameStack, subspaces
from visualenv.train.model_files import load_model, stacked_like
from visualenv.train.reproducible import machine_record, pinned_inference
from visualenv.train.run_folder import legacy_eval_seed, load_evaluations, read_run
from visualenv.train.run_settings import RESULT_KEYS

SEED_BAND = 2**32  # each purpose's seeds lie in their own band of this width
SELECTION_BAND, FINAL_BAND, FRESH_BAND = 1, 2, 3
# `eval` of a model without a run: no run trains, selects or reports on these episodes
FRESH_SEED = FRESH_BAND * SEED_BAND
FINAL_EPISODES = 100  # the final evaluation's episodes by default
CONFIDENCE = 0.95
Z_95 = 1.959963984540054  # standard normal quantile of 0.975
BOOTSTRAP_RESAMPLES = 10_000
CI_METHOD = (
    "95 %: percentile bootstrap of the mean (10,000 resamples) for return and length, Wilson score for the success rate"
)


def selection_seed(train_seed: int) -> int:
    """The seed of a run's periodic evaluations, which pick its best model."""
    return SELECTION_BAND * SEED_BAND + train_seed


def final_seed(train_seed: int) -> int:
    """The seed of a run's final evaluation (results.json): episodes never used in training or selection."""
    return FINAL_BAND * SEED_BAND + train_seed


def seed_purpose(seed: int) -> str:
    """Which use a seed's band is for: 'training', 'selection', 'final' or 'fresh'."""
    return ("training", "selection", "final", "fresh")[min(seed // SEED_BAND, FRESH_BAND)]


def selection_record(run_dir: Path, seed: int) -> dict[str, Any] | None:
    """The periodic evaluation that picked the best model (the first with the highest mean return, as SB3's EvalCallback picks)."""
    saved = load_evaluations(run_dir) or {}
    if "timesteps" not in saved or "results" not in saved:
        return None
    timesteps, returns, successes = saved["timesteps"], saved["results"], saved.get("successes")
    if len(timesteps) == 0:
        return None
    best = int(np.argmax(returns.mean(axis=1)))
    record: dict[str, Any] = {
        "eval_seed": seed,
        "evaluations": len(timesteps),
        "best_at_step": int(timesteps[best]),
        "episodes": int(returns.shape[1]),
        "mean_reward": float(returns[best].mean()),
    }
    if successes is not None and len(successes) == len(timesteps):
        record["success_rate"] = float(np.mean(successes[best]))
    return record


def make_eval_env(
    spec_path: str,
    *,
    seed: int,
    frame_stack: int,
    render: bool = True,
    transpose: bool = True,
    distractions: float | str | list[float] | dict[str, Any] | None = None,
    trust_code: bool = False,
) -> Any:
    """One in-process env seeded `seed`, frames stacked and (`transpose`) images channels first, as SB3 does to the training env.

    RLlib's policies take the images channels last (``transpose=False``). `distractions`: the env's difficulty
    (docs/distractions.md), else the spec's. `trust_code`: the spec's ``dynamics.python`` may be imported.
    """
    from stable_baselines3.common.vec_env import VecTransposeImage

    from visualenv.env.sb3_vec import make_sb3_vec

    options: dict[str, Any] = {} if render else {"render": False}
    if distractions is not None:
        options["distractions"] = distractions
    if trust_code:
        options["trust_code"] = True
    env = make_sb3_vec(spec_path, 1, seed=seed, frame_stack=frame_stack, threads=1, **options)
    return VecTransposeImage(env) if transpose and channels_last_images(env.observation_space) else env


def channels_last_images(space: Any) -> bool:
    """Whether SB3 wraps an env of this space in VecTransposeImage (its rule in ``BaseAlgorithm._wrap_env``)."""
    from stable_baselines3.common.preprocessing import is_image_space, is_image_space_channels_first

    return any(is_image_space(s) and not is_image_space_channels_first(s) for s in subspaces(space).values())  # type: ignore[arg-type]


def final_evaluation(model: Any, vec_env: Any, episodes: int, seed: int, *, resets_before: int = 0) -> dict[str, Any]:
    """`episodes` deterministic episodes, the first from a reset seeded `seed`: the figures of results.json.

    `resets_before` resets the env that many times first (the first of them seeded):
    the final evaluation of runs made before results.json recorded ``eval_seed`` came
    after the periodic evaluations on the same env (see :func:`recorded_evaluation`).
    """
    vec_env.seed(seed)
    for _ in range(resets_before):
        vec_env.reset()
    results = evaluate(model, vec_env, episodes)
    results["eval_seed"] = seed
    if resets_before:
        results["resets_before"] = resets_before
    return results


def evaluate(model: Any, vec_env: Any, episodes: int) -> dict[str, Any]:
    """Run `episodes` deterministic episodes; mean/std return, mean length, success rate, their intervals."""
    returns: list[float] = []
    lengths: list[int] = []
    successes: list[bool] = []
    obs = vec_env.reset()
    ret, length = 0.0, 0
    with pinned_inference() as pinned:
        while len(returns) < episodes:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, done, infos = vec_env.step(action)
            ret += float(reward[0])
            length += 1
            if done[0]:
                returns.append(ret)
                lengths.append(length)
                successes.append(bool(infos[0].get("is_success", False)))
                ret, length = 0.0, 0
    return {
        "episodes": episodes,
        "mean_reward": float(np.mean(returns)),
        "std_reward": float(np.std(returns)),
        "mean_length": float(np.mean(lengths)),
        "success_rate": float(np.mean(successes)),
        "reward_ci95": bootstrap_mean_interval(returns),
        "length_ci95": bootstrap_mean_interval(lengths),
        "success_ci95": wilson_interval(sum(successes), len(successes)),
        "ci_method": CI_METHOD,
        # each episode in order: a shorter evaluation with the same seed plays the first of them again
        "per_episode": {"returns": returns, "lengths": lengths, "successes": successes},
        # what a replay on another machine needs to know (visualenv.train.reproducible)
        "machine": machine_record(pinned),
    }


def bootstrap_mean_interval(
    values: Any, resamples: int = BOOTSTRAP_RESAMPLES, confidence: float = CONFIDENCE
) -> list[float]:
    """Percentile bootstrap interval of the mean (resampling seed 0: the same values give the same interval)."""
    data = np.asarray(values, dtype=np.float64)
    rng = np.random.default_rng(0)
    means = np.concatenate(
        [
            data[rng.integers(0, len(data), (n, len(data)))].mean(axis=1)
            for n in np.diff(np.r_[0:resamples:1000, resamples])
        ]
    )
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(means, [tail, 100 - tail])
    return [float(low), float(high)]


def wilson_interval(successes: int, n: int, z: float = Z_95) -> list[float]:
    """Wilson score interval of a success rate (95 % with the default z)."""
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [0.0 if successes == 0 else centre - half, 1.0 if successes == n else centre + half]


# -- what a run recorded about its final evaluation ----------------------------------------------------------


@dataclass
class RecordedEvaluation:
    """How a run evaluated its model at the end: what `visualenv eval` replays to reproduce results.json."""

    seed: int
    episodes: int
    algo: str
    frame_stack: int
    render: bool
    resets_before: int = 0
    results: dict[str, Any] | None = None  # the run's results.json
    note: str | None = None  # why the replay may not match results.json


def recorded_evaluation(run_dir: Path) -> RecordedEvaluation | None:
    """The final evaluation recorded in `run_dir` (results.json, config.json); None without config.json.

    An older run's is migrated (:func:`~visualenv.train.run_folder.migrate`): runs before ``eval_seed`` replay
    after the resets their periodic evaluations made. A run without results.json replays the legacy stream.
    """
    run = read_run(run_dir)
    if run.record is None:
        return None
    config, results = run.config, run.results
    render = config["render"]
    common = {"algo": config["algo"], "render": render, "frame_stack": config["frame_stack"] if render else 0}
    if results is None:
        return RecordedEvaluation(
            seed=legacy_eval_seed(config["seed"]), episodes=config["final_eval_episodes"], **common
        )
    return RecordedEvaluation(
        seed=results["eval_seed"],
        episodes=results["episodes"],
        results=results,
        resets_before=results.get("resets_before", 0),
        note=run.note,
        **common,
    )


class RandomPolicy:
    """Uniform random actions from the action space, drawn from their own seeded generator: the baseline beside a trained agent.

    Its actions ignore the observation, so it is evaluated on the state-only env:
    the same episodes (Blender draws no random numbers) without rendering them.
    """

    def __init__(self, action_space: Any, seed: int) -> None:
        self.action_space = action_space
        self.action_space.seed(seed)

    def predict(self, observation: Any, deterministic: bool = True) -> tuple[np.ndarray, None]:
        return np.array([self.action_space.sample()]), None


def evaluate_random(
    spec: str, *, episodes: int | None = None, seed: int | None = None, trust_code: bool = False
) -> dict[str, Any]:
    """`visualenv eval --model random`: uniform random actions on `episodes` episodes from a reset seeded `seed` (default :data:`FRESH_SEED`)."""
    from visualenv.env.registration import resolve

    seed = FRESH_SEED if seed is None else seed
    vec_env = make_eval_env(str(resolve(spec)), seed=seed, frame_stack=1, render=False, trust_code=trust_code)
    try:
        return final_evaluation(RandomPolicy(vec_env.action_space, seed), vec_env, episodes or FINAL_EPISODES, seed)
    finally:
        vec_env.close()


def evaluate_model(
    spec: str,
    model_path: str | Path,
    *,
    algo: str | None = None,
    episodes: int | None = None,
    seed: int | None = None,
    trust_pickle: bool = False,
    distractions: float | str | list[float] | dict[str, Any] | None = None,
    trust_code: bool = False,
) -> tuple[dict[str, Any], RecordedEvaluation | None]:
    """`visualenv eval`: the model's deterministic evaluation on `spec`, and what its run recorded (if found beside it).

    Unset arguments take the run's values (config.json and results.json beside the model),
    else PPO, 100 episodes and :data:`FRESH_SEED`; the run's final evaluation is replayed when the
    seed is the run's. `trust_pickle`: a pickle-based model may load (:func:`~visualenv.train.model_files.load_model`).
    `distractions`: the observations distracted at this difficulty, or by this distractions section (the results
    say so in ``distractions``).
    `trust_code`: the spec's ``dynamics.python`` may be imported (docs/security.md).
    """
    from gymnasium import spaces

    from visualenv.env import VisualEnv
    from visualenv.env.registration import resolve
    from visualenv.spec import load_spec

    recorded = recorded_evaluation(Path(model_path).parent)
    if seed is None:
        seed = recorded.seed if recorded else FRESH_SEED
    replayed = recorded if recorded is not None and seed == recorded.seed else None
    mkl.pin()  # before the model is built: its initialisation calls MKL, which then keeps its mode
    model = load_model(str(model_path), algo or (recorded.algo if recorded else "ppo"), trust_pickle=trust_pickle)
    space = model.observation_space
    render = recorded.render if recorded else not (isinstance(space, spaces.Box) and len(space.shape) == 1)
    spec_path = str(resolve(spec))
    # refuses a model of another env
    probe = stacked_like(VisualEnv(load_spec(spec_path), render=render, trust_code=trust_code), model, str(model_path))
    probe.close()
    frame_stack = recorded.frame_stack if recorded else (probe.depth if isinstance(probe, FrameStack) else 1)
    vec_env = make_eval_env(
        spec_path,
        seed=seed,
        frame_stack=frame_stack,
        render=render,
        transpose=not channels_last_images(space),
        distractions=distractions,
        trust_code=trust_code,
    )
    try:
        results = final_evaluation(
            model,
            vec_env,
            episodes or (recorded.episodes if recorded else FINAL_EPISODES),
            seed,
            resets_before=replayed.resets_before if replayed else 0,
        )
    finally:
        vec_env.close()
    if distractions is not None:
        results["distractions"] = distractions
    return results, replayed


#: a replay on a machine unlike the recording one (another CPU's renderer kernels, other versions) must give every
#: episode the same outcome, a length within this many steps and a return within RETURN_TOLERANCE of its magnitude:
#: the largest drift seen, LunarLanding's first episode under Cycles' SSE4.2 kernel, was well within it
#: (results/benchmarks/cross-machine-replay.md)
LENGTH_TOLERANCE = 2
RETURN_TOLERANCE = 0.02
TOLERANCE_TEXT = f"the same outcome, length within {LENGTH_TOLERANCE} steps, return within {RETURN_TOLERANCE:.0%}"


def differences(results: dict[str, Any], recorded: dict[str, Any], *, tolerant: bool = False) -> list[str]:
    """The figures of results.json that `results` does not reproduce: exactly, or `tolerant` (see TOLERANCE_TEXT).

    An evaluation of fewer episodes than results.json's (same seed) is compared episode by
    episode with the first of results.json's ``per_episode`` records; so is a tolerant one.
    """
    played, kept = results.get("per_episode", {}), recorded.get("per_episode", {})
    n = results.get("episodes", 0)
    by_episode = len(kept.get("returns", [])) >= n and len(played.get("returns", [])) == n
    if by_episode and (tolerant or n < recorded.get("episodes", 0)):
        return [
            f"episode {i}: {key} {played[key][i]} (results.json: {kept[key][i]})"
            for key in ("returns", "lengths", "successes")
            for i in range(n)
            if not _close(key, played[key][i], kept[key][i], tolerant)
        ]
    return [
        f"{key} {results.get(key)} (results.json: {recorded[key]})"
        for key in RESULT_KEYS
        if key in recorded and not _close(key, results.get(key), recorded[key], tolerant)
    ]


def _close(key: str, played: Any, kept: Any, tolerant: bool) -> bool:
    if not tolerant or key in ("successes", "success_rate", "episodes") or not isinstance(played, (int, float)):
        return bool(played == kept)
    if key in ("lengths", "mean_length"):
        return abs(played - kept) <= LENGTH_TOLERANCE
    return abs(played - kept) <= RETURN_TOLERANCE * max(1.0, abs(kept))


#: episodes that cannot replay (a chaotic agent on another CPU's kernels) are compared as a sample: each total must lie
#: where the totals of as many episodes drawn from results.json's fall this often
SAMPLE_CONFIDENCE = 0.999


def sample_differences(results: dict[str, Any], recorded: dict[str, Any]) -> list[str]:
    """The totals of `results`' episodes (return, length, successes) that as many episodes drawn at random from
    results.json's would give less often than SAMPLE_CONFIDENCE ([] if the episodes could be a sample of those)."""
    played, kept = results.get("per_episode", {}), recorded.get("per_episode", {})
    n = len(played.get("returns", []))
    if not n or not kept.get("returns"):
        return []
    draws = np.random.default_rng(0).integers(0, len(kept["returns"]), (BOOTSTRAP_RESAMPLES, n))
    wrong = []
    for key in ("returns", "lengths", "successes"):
        totals = np.asarray(kept[key], dtype=np.float64)[draws].sum(axis=1)
        low, high = np.quantile(totals, [(1 - SAMPLE_CONFIDENCE) / 2, (1 + SAMPLE_CONFIDENCE) / 2])
        total = float(np.sum(np.asarray(played[key], dtype=np.float64)))
        if not low <= total <= high:
            wrong.append(f"{key} of {n} episodes total {total:g}, where {n} of results.json's give {low:g} to {high:g}")
    return wrong


def replays_prefix(results: dict[str, Any], recorded: dict[str, Any]) -> bool:
    """Whether `results` (fewer episodes, the same seed) can be checked against results.json's per-episode records."""
    return (
        0 < results.get("episodes", 0) < recorded.get("episodes", 0)
        and len(recorded.get("per_episode", {}).get("returns", [])) == recorded["episodes"]
    )


def declares_success(spec: str) -> bool:
    """Whether the spec (a path or an id) has a success outcome: else an evaluation has no success rate to show."""
    from visualenv.env.registration import resolve
    from visualenv.spec import load_spec

    return load_spec(resolve(spec)).spec.declares_success


def evaluation_line(steps: int, returns: Any, successes: Any = None) -> str:
    """One periodic evaluation as a line of text (``train --no-progress`` prints it: a log file shows the run's course)."""
    values = np.asarray(returns, dtype=np.float64)
    line = f"eval at {steps} steps: mean return {values.mean():.2f} +- {values.std():.2f} over {values.size} episodes"
    if successes is not None and len(successes):
        line += f", success {int(np.sum(successes))}/{len(successes)}"
    return line
