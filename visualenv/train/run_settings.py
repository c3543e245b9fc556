"""What a run's config.json and results.json may hold: every setting's type and bounds, by backend.

:mod:`visualenv.train.run_folder` reads and writes the files and migrates older runs; this module is the format they are
checked against (a value of a file from elsewhere is believed only once its rule holds).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from visualenv.errors import ConfigError

FORMAT = "visualenv-run"
FORMAT_VERSION = 2  # 1: config.json before run_folder owned it (no format key); see run_folder.migrate
BACKENDS = ("sb3", "rllib", "distill")
MAX_TRAIN_SEED = 2**31 - 1  # `train --seed`: with up to 2**31 envs, training seeds stay below the selection band
MAX_RESETS_BEFORE = 10_000  # resets `eval` replays before an older run's final evaluation (each renders a frame)


class RunFolderError(ConfigError):
    """A run folder's config.json or results.json that this code did not write, or that holds a value out of bounds."""


# -- the settings config.json may hold, and their bounds ------------------------------------------------------------


@dataclass(frozen=True)
class Rule:
    """What a setting may be: a value of `kind` from `low` to `high`, one of `choices`, or None where `optional`."""

    kind: type | tuple[type, ...]
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    optional: bool = False
    above_low: bool = False  # low itself excluded
    below_high: bool = False  # high itself excluded

    def problem(self, value: Any) -> str | None:
        """Why `value` breaks the rule, or None."""
        if value is None:
            return None if self.optional else "expected a value, got null"
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        of_kind = isinstance(value, self.kind) and (self.kind is bool) == isinstance(value, bool)
        if not (number if self.kind is float else of_kind):
            return f"expected {self._kind_name()}, got {type(value).__name__} {value!r}"
        if self.choices and value not in self.choices:
            return f"expected one of {', '.join(self.choices)}, got {value!r}"
        if number and not (math.isfinite(value) and self._within(value)):
            return f"expected {self._kind_name()}{self._bounds()}, got {value!r}"
        if self.kind is str and not value:
            return "expected a non-empty text"
        return None

    def _kind_name(self) -> str:
        kinds = self.kind if isinstance(self.kind, tuple) else (self.kind,)
        return " or ".join(_NAMES[k] for k in kinds)

    def _within(self, value: float) -> bool:
        above = self.low is None or (value > self.low if self.above_low else value >= self.low)
        return above and (self.high is None or (value < self.high if self.below_high else value <= self.high))

    def _bounds(self) -> str:
        low = "" if self.low is None else f" {'above' if self.above_low else 'from'} {_number(self.low)}"
        high = (
            ""
            if self.high is None
            else f" {'below' if self.below_high else 'to' if low else 'up to'} {_number(self.high)}"
        )
        return low + high or " (finite)"


def _number(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def finite_number(value: Any) -> bool:
    """Whether a value read from JSON is a number (not true/false) a float holds finitely: not NaN, not infinite, not
    an integer beyond a float's range (JSON's integers have no bound)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


_NAMES = {int: "an integer", float: "a number", bool: "true or false", str: "a text", dict: "a mapping", list: "a list"}

COUNT = Rule(int, 1, 2**16)  # envs, runners, workers
STEPS = Rule(int, 1, 10**12)
EPISODES = Rule(int, 1, 10**6)
SETTINGS: dict[str, Rule] = {
    **dict.fromkeys(("spec", "teacher"), Rule(str)),
    **dict.fromkeys(("steps", "eval_every"), STEPS),
    **dict.fromkeys(("envs", "env_runners", "envs_per_runner"), COUNT),
    **dict.fromkeys(("eval_episodes", "final_eval_episodes", "rounds", "episodes"), EPISODES),
    **dict.fromkeys(("render", "progress", "pin", "batched"), Rule(bool)),
    "algo": Rule(str, choices=("ppo", "a2c", "dqn", "sac", "dagger")),
    "workers": Rule(int, 1, 2**16, optional=True),
    "frame_stack": Rule(int, 1, 64),
    "seed": Rule(int, 0, MAX_TRAIN_SEED),
    "hyperparams": Rule(dict),
    "render_device": Rule(str, choices=("cpu", "gpu"), optional=True),
    "augment": Rule(str, choices=("shift",), optional=True),
    "backend": Rule(str, choices=("rllib",)),
    # distillation
    "student": Rule(str, optional=True),
    "mixing": Rule(float, 0, 1),
    "epochs": Rule(float, 0, 10**6, above_low=True),
    "batch_size": Rule(int, 1, 2**20),
    "learning_rate": Rule(float, 0, 1, above_low=True),
    "shift": Rule(int, 0, 1024),
    "state_loss": Rule(float, 0, 10**6),
    "consistency": Rule(float, 0, 10**6),
    "rotate": Rule(float, 0, 180),
    "zoom": Rule(float, 0, 1, below_high=True),  # a scale of 1 - zoom must stay above 0
    "distractions": Rule((list, dict), optional=True),  # [difficulty], [low, high], or a distractions section
    "encoder": Rule(str, choices=("nature", "drq")),  # distill.STUDENT_ENCODERS (distill imports this module)
}
_COMMON = ("spec", "algo", "frame_stack", "eval_episodes", "final_eval_episodes", "seed", "render", "progress")
#: each backend's settings: those of its first format, then (with the value an older run takes) those added since
KEYS: dict[str, tuple[str, ...]] = {
    "sb3": (*_COMMON, "steps", "envs", "eval_every", "hyperparams"),
    "rllib": (*_COMMON, "steps", "env_runners", "envs_per_runner", "eval_every", "hyperparams", "backend"),
    "distill": (*_COMMON, "teacher", "rounds", "episodes", "mixing", "epochs", "batch_size", "learning_rate", "shift"),
}
ADDED: dict[str, dict[str, Any]] = {
    "sb3": {"pin": True, "batched": False, "workers": None, "render_device": None, "augment": None},
    "rllib": {"pin": True, "batched": False},
    "distill": {
        "student": None,
        "distractions": None,
        "state_loss": 0.0,
        "rotate": 0.0,
        "zoom": 0.0,
        "encoder": "nature",
        "consistency": 0.0,
    },
}
ALGORITHMS = {"sb3": ("ppo", "a2c", "dqn", "sac"), "rllib": ("ppo",), "distill": ("dagger",)}
RECORD_KEYS: dict[str, Rule] = {
    **dict.fromkeys(("command", "spec_path"), Rule(str)),
    **dict.fromkeys(("config", "versions", "teacher", "student", "spec"), Rule(dict)),
    "format": Rule(str, choices=(FORMAT,)),
    "format_version": Rule(int, 1, FORMAT_VERSION),
    "backend": Rule(str, choices=BACKENDS),
    "resumes": Rule(list),
}


def settings(backend: str) -> tuple[str, ...]:
    """The settings a current config.json of `backend` holds, each exactly once."""
    return KEYS[backend] + tuple(ADDED[backend])


def _check(rules: dict[str, Rule], values: dict[str, Any], where: str, name: str) -> None:
    for key, value in values.items():
        rule = rules.get(key)
        if rule is None:
            raise RunFolderError(f"{where}: unknown key {name}{key}")
        problem = rule.problem(value)
        if problem:
            raise RunFolderError(f"{where}: {name}{key}: {problem}")


def check_record(record: Any, where: str = "config.json") -> dict[str, Any]:
    """`record` if it is a current config.json: every setting of its backend there, of its type and in bounds."""
    if not isinstance(record, dict) or not isinstance(record.get("config"), dict):
        raise RunFolderError(f"{where}: not the config.json of a visualenv run (no 'config' mapping of settings)")
    _check(RECORD_KEYS, record, where, "")
    if record.get("format_version") != FORMAT_VERSION or "backend" not in record:
        raise RunFolderError(
            f"{where}: expected format_version {FORMAT_VERSION} and a backend (read_config migrates an older run's)"
        )
    backend, config = record["backend"], record["config"]
    missing = [k for k in settings(backend) if k not in config]
    if missing:
        raise RunFolderError(f"{where}: a {backend} run's config lacks {', '.join(missing)}")
    extra = [k for k in config if k not in settings(backend)]
    if extra:
        raise RunFolderError(f"{where}: unknown setting config.{extra[0]} for a {backend} run")
    _check(SETTINGS, config, where, "config.")
    if config["algo"] not in ALGORITHMS[backend]:
        raise RunFolderError(
            f"{where}: config.algo: a {backend} run trains {', '.join(ALGORITHMS[backend])}, not {config['algo']!r}"
        )
    if config.get("workers") is not None and config["workers"] > config["envs"]:
        raise RunFolderError(f"{where}: config.workers: {config['workers']} workers for {config['envs']} envs")
    for resume in record.get("resumes", []):
        if not (
            isinstance(resume, dict)
            and isinstance(resume.get("command"), str)
            and isinstance(resume.get("hyperparams"), dict)
        ):
            raise RunFolderError(f"{where}: resumes: expected a command and its hyperparameters, got {resume!r}")
    return record


RESULT_RULES: dict[str, Rule] = {
    **dict.fromkeys(("per_episode", "evaluated"), Rule(dict)),
    **dict.fromkeys(("machine", "selection"), Rule(dict, optional=True)),
    **dict.fromkeys(("std_reward", "mean_length", "wall_time_s"), Rule(float, 0)),
    "segment_wall_time_s": Rule(float, 0),
    "episodes": EPISODES,
    "mean_reward": Rule(float),
    "success_rate": Rule(float, 0, 1),
    "eval_seed": Rule(int, 0, 2**63 - 1),
    "resets_before": Rule(int, 0, MAX_RESETS_BEFORE),
    "steps": Rule(int, 0, 10**12),
    "model": Rule(str),
    "stopped_early": Rule(bool),
}
#: what results.json has always held
RESULT_KEYS = ("episodes", "mean_reward", "std_reward", "mean_length", "success_rate")


def check_results(results: Any, where: str = "results.json") -> dict[str, Any]:
    """`results` if its figures are of their type and in bounds (other keys are kept as they are)."""
    if not isinstance(results, dict):
        raise RunFolderError(f"{where}: expected a mapping of the evaluation's figures, got {type(results).__name__}")
    missing = [k for k in RESULT_KEYS if k not in results]
    if missing:
        raise RunFolderError(f"{where}: not the results of a visualenv evaluation (no {', '.join(missing)})")
    _check(RESULT_RULES, {k: v for k, v in results.items() if k in RESULT_RULES}, where, "")
    per_episode = results.get("per_episode", {})
    for key in ("returns", "lengths", "successes"):
        episodes = per_episode.get(key, [])
        if key in per_episode and not (isinstance(episodes, list) and len(episodes) == results["episodes"]):
            raise RunFolderError(f"{where}: per_episode.{key}: expected a list of {results['episodes']} episodes")
    return results
