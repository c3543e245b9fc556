"""One env and a batch's lane follow the same episode rules: a differential test, step by step.

Single env i made and reset with seed s + i and env i of a BatchedVectorEnv reset with seed s
are given the same random actions for a few hundred steps (state-only observations, so no
Blender): observations, rewards, terminated, truncated and info (state, steps, outcome,
milestones, is_success, error) must be equal, autoreset included. A fault must be the same
fault: under ``on_fault: raise`` the batch raises the message of the first env that faulted,
prefixed with its index (``env 2: ...``); under ``terminate`` each env's episode ends with the
same ``info["error"]``. Every bundled spec runs, then hostile ones: a state past float32, a
NaN action, a ``dynamics.python`` hook that raises, a division by zero that the batch's
element-wise code would clip away.
"""

from __future__ import annotations

import ast
import itertools
import math
import operator
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from visualenv.compiler.batch_functions import OPERATORS, float_errors, vector_functions
from visualenv.env.batch import BatchedVectorEnv
from visualenv.env.visual_env import VisualEnv
from visualenv.errors import StepError
from visualenv.expr.codegen import power
from visualenv.expr.functions import FUNCTIONS
from visualenv.spec import load_spec_text
from visualenv.spec.loader import LoadedSpec, load_spec

#: a NaN action reaches MuJoCo in a batch, which steps every env's simulation at once (the env's lane then faults as one env)
pytestmark = pytest.mark.filterwarnings("ignore:MuJoCo. Nan, Inf or huge value:RuntimeWarning")

SPECS = Path(__file__).parents[2] / "specs"
BUNDLED = (
    sorted(SPECS.glob("*.yaml")) + sorted((SPECS / "mujoco").glob("*.yaml")) + sorted((SPECS / "dmc").glob("*.yaml"))
)
N = 4
SEED = 20
#: the DMC domains whose comparisons run in every suite (PlaNet's six tasks'); the rest run in the slow tier
EVERY_RUN = {"cartpole_swingup", "cheetah_run", "walker_walk", "reacher_easy", "ball_in_cup_catch", "finger_spin"}


def tiered(specs: list[Path]) -> list[Any]:
    """`specs`, a DMC one outside :data:`EVERY_RUN` marked slow (each costs seconds: the suite stays under its bar)."""
    return [
        pytest.param(s, marks=pytest.mark.slow) if s.parent.name == "dmc" and s.stem not in EVERY_RUN else s
        for s in specs
    ]


#: a state past float32 after four grows (float64 holds it: only the observation overflows), a milestone on the way
OVERFLOW = """\
id: Overflow-v0
state:
  x: {init: "uniform(1, 2)"}
  t: {init: 0.0}
actions:
  discrete: [{grow: 0}, {grow: 1}]
dynamics:
  update:
    x: "x * 1e10 if grow > 0 else x"
    t: t + 1
reward: "1 / x if x != 0 else 0"
outcomes:
  huge: {when: x > 1e25, end: none, success: true}
max_steps: 40
"""

#: a continuous spec with a milestone, a conditional, an ending outcome and truncation (the NaN action's target)
FEATURES = """\
id: Features-v0
params: {k: 0.5}
state:
  x: {init: "uniform(-1, 1)"}
  v: {init: 0.0}
actions:
  continuous: {push: {low: -1, high: 1}, brake: {low: 0, high: 1}}
dynamics:
  let: {drag: "v * brake if abs(v) > 0.1 else 0.0"}
  update:
    x: x + v
    v: clip(v + push * k - drag, -2, 2)
reward: "-abs(x) + (1 if 0.2 < x < 0.5 else 0)"
outcomes:
  halfway: {when: abs(x) > 1.5, reward: 1, end: none, success: true}
  away: {when: abs(x) > 3, reward: -5}
max_steps: 40
"""

#: every function of the language whose numpy loop may differ from Python's math in the last bit (SIMD versions)
CURVES = """\
id: Curves-v0
state:
  x: {init: "uniform(-0.9, 0.9)"}
  y: {init: "uniform(-0.9, 0.9)"}
actions:
  continuous: {push: {low: -1, high: 1}}
dynamics:
  update:
    x: "clip(x + 0.1 * tan(push) + 0.01 * atan2(y, x) - 0.05 * tanh(x) + 0.01 * log(2 + y, 3), -1, 1)"
    y: "clip(0.9 * y + 0.1 * sinh(push) + 0.01 * asin(x) + 0.01 * acos(y) - 0.01 * atan(y) + 0.001 * exp(x), -1, 1)"
reward: "exp(-abs(x)) + log(1 + y * y) + 0.1 * cosh(x) + sin(x) * cos(y)"
outcomes:
  edge: {when: abs(x) > 0.99, end: terminate}
max_steps: 50
"""

#: the user's Python dynamics raises once the walk passes the wall
HOOK = """\
id: Hook-v0
params: {wall: 2.2}
state: {x: {init: "uniform(-1, 1)"}}
actions: {discrete: [{push: -1}, {push: 1}]}
dynamics: {python: "tests.fixtures.dynamics_hook:walks_to_the_wall"}
reward: -abs(x)
outcomes:
  centred: {when: abs(x) < 0.1, end: none}
max_steps: 30
"""

#: 1 / x when the walk reaches 0: a division by zero that clip() would turn into 1 in numpy's element-wise code
DIVISION = """\
id: Division-v0
state: {x: {init: 2.0}}
actions: {discrete: [{dx: -1}, {dx: 1}]}
dynamics: {update: {x: x + dx}}
reward: clip(1 / x, -1, 1)
outcomes:
  away: {when: abs(x) > 5, end: truncate}
max_steps: 60
"""

#: a MuJoCo slide whose step divides by zero, or floors a NaN action, before the MuJoCo step (which the batch takes for all at once)
SLIDE_MODEL = """\
<mujoco model="slide">
  <option timestep="0.01"/>
  <worldbody>
    <body name="cart">
      <joint name="slide" type="slide" axis="1 0 0"/>
      <geom name="block" type="box" size="0.1 0.1 0.1" mass="1"/>
    </body>
  </worldbody>
  <actuator><motor name="push" joint="slide" gear="20"/></actuator>
</mujoco>
"""
SLIDE = """\
id: Slide-v0
physics:
  model: slide.xml
  frame_skip: 2
  reset: {values: {qvel_slide: 'uniform(-1, 1)'}}
actions:
  continuous: {ctrl_push: {low: -1, high: 1}}
dynamics: {let: {inv: 'clip(1 / round(qvel_slide * 4), -1, 1)', notch: 'floor(ctrl_push * 2)'}}
reward: inv + 0 * notch
outcomes:
  far: {when: abs(qpos_slide) > 1, end: terminate}
max_steps: 30
"""

HOSTILE = {"overflow": OVERFLOW, "hook": HOOK, "division": DIVISION, "physics": SLIDE, "curves": CURVES}


def hostile(case: str, on_fault: str, folder: Path) -> LoadedSpec:
    """A hostile spec with ``on_fault`` set, read as if from `folder` (where the physics one finds its model)."""
    (folder / "slide.xml").write_text(SLIDE_MODEL, encoding="utf-8")
    return with_fault_policy(load_spec_text(HOSTILE[case], name=f"{case}.yaml", base_dir=folder), on_fault)


def with_fault_policy(loaded: LoadedSpec, on_fault: str) -> LoadedSpec:
    """The same spec with ``on_fault`` set (a bundled spec keeps its file, its line map and its base folder)."""
    return LoadedSpec(loaded.spec.model_copy(update={"on_fault": on_fault}), loaded.source, loaded.base_dir)


def lane_info(info: dict[str, Any], i: int, names: list[str]) -> dict[str, Any]:
    """Env i's info out of a vector info, in a single env's layout."""
    out = {
        "state": {n: info["state"][n][i] for n in names},
        "steps": info["steps"][i],
        "outcome": info["outcome"][i],
        "milestones": info["milestones"][i],
        "is_success": info["is_success"][i],
    }
    if "error" in info and info["_error"][i]:
        out["error"] = info["error"][i]
    return out


def assert_same_obs(batch_obs: np.ndarray, single_obs: np.ndarray, where: str) -> None:
    assert batch_obs.dtype == single_obs.dtype and batch_obs.shape == single_obs.shape, where
    assert np.array_equal(batch_obs, single_obs, equal_nan=True), f"{where}: {batch_obs} != {single_obs}"


def assert_same_info(batch_info: dict[str, Any], single_info: dict[str, Any], where: str) -> None:
    assert batch_info.keys() == single_info.keys(), f"{where}: {sorted(batch_info)} != {sorted(single_info)}"
    for key, value in single_info.items():
        assert batch_info[key] == value, f"{where}: info[{key!r}] {batch_info[key]!r} != {value!r}"


def differential(
    loaded: LoadedSpec,
    steps: int,
    nan_rate: float = 0.0,
    mode: AutoresetMode = AutoresetMode.NEXT_STEP,
    repeat: int = 1,
    n: int = N,
) -> dict[str, int]:
    """Step a batch of n and n single envs with the same random actions; count what happened (episodes ended, faults).
    `repeat`: the action repeat of both (DeepMind Control's tasks default to theirs: compared with 1, and with it apart)."""
    # trust_code: the hook case imports the test's own module (tests/fixtures/dynamics_hook.py)
    batch = BatchedVectorEnv(loaded, n, render=False, autoreset_mode=mode, action_repeat=repeat, trust_code=True)
    actions = random_actions(batch.action_space, SEED, nan_rate)
    singles = [VisualEnv(loaded, render=False, action_repeat=repeat, trust_code=True) for _ in range(n)]
    names = batch.program.state_names
    counts = {"ended": 0, "errors": 0, "raised": 0}
    obs, info = batch.reset(seed=SEED)
    for i, env in enumerate(singles):
        single_obs, single_info = env.reset(seed=SEED + i)
        assert_same_obs(obs[i], single_obs, f"reset, env {i}")
        assert_same_info(lane_info(info, i, names), single_info, f"reset, env {i}")
    done = np.zeros(N, dtype=bool)
    for t in range(steps):
        action = actions(t)
        try:
            obs, rewards, terminated, truncated, info = batch.step(action)
            raised = None
        except StepError as err:
            raised = str(err)
        expected: str | None = None
        for i, env in enumerate(singles):
            where = f"step {t}, env {i}"
            if done[i] and mode == AutoresetMode.NEXT_STEP:
                single_obs, single_info = env.reset()
                single = (single_obs, 0.0, False, False, single_info)
            else:
                try:
                    single = env.step(action[i] if batch.program.discrete is None else int(action[i]))
                except StepError as err:
                    expected = expected or f"env {i}: {err}"
                    continue
            if raised is not None:
                continue
            single_obs, reward, term, trunc, single_info = single
            counts["errors"] += "error" in single_info
            if mode == AutoresetMode.SAME_STEP and (term or trunc):
                assert info["_final_obs"][i] and info["_final_info"][i], where
                assert_same_obs(info["final_obs"][i], single_obs, where + " (final)")
                assert_same_info(lane_info(info["final_info"], i, names), single_info, where + " (final)")
                single_obs, single_info = env.reset()
            assert_same_obs(obs[i], single_obs, where)
            assert (rewards[i], terminated[i], truncated[i]) == (reward, term, trunc), where
            assert_same_info(lane_info(info, i, names), single_info, where)
        assert raised == expected, f"step {t}: the batch raised {raised!r}, one env {expected!r}"
        if raised is not None:
            counts["raised"] += 1
            break
        done = terminated | truncated
        counts["ended"] += int(done.sum())
    batch.close()
    return counts


def random_actions(batch_space: Any, seed: int, nan_rate: float = 0.0) -> Callable[[int], np.ndarray]:
    """The actions of step t (the same in both), drawn up front; continuous ones NaN in one input now and then."""
    rng = np.random.default_rng(seed)
    drawn: dict[int, np.ndarray] = {}

    def at(t: int) -> np.ndarray:
        if t not in drawn:
            if batch_space.dtype.kind == "i":
                drawn[t] = rng.integers(0, batch_space.nvec[0], len(batch_space.nvec)).astype(batch_space.dtype)
            else:
                low, high = batch_space.low, batch_space.high
                action = rng.uniform(low, high).astype(batch_space.dtype)
                for i in np.flatnonzero(rng.random(len(action)) < nan_rate):
                    action[i, rng.integers(action.shape[1])] = np.nan
                drawn[t] = action
        return drawn[t]

    return at


@pytest.mark.parametrize("spec", tiered(BUNDLED), ids=lambda p: p.stem)
def test_every_bundled_spec_runs_the_same_episodes_in_one_env_and_in_a_batch(spec: Path) -> None:
    loaded = load_spec(spec)
    steps = 120 if loaded.spec.physics is not None else 300  # MuJoCo steps cost more
    counts = differential(loaded, steps)
    assert counts["raised"] == 0 and counts["errors"] == 0
    assert counts["ended"] > 0 or loaded.spec.max_steps > steps, "no episode ended: autoreset went untested"


@pytest.mark.parametrize("spec", tiered(sorted((SPECS / "dmc").glob("*.yaml"))), ids=lambda p: p.stem)
def test_a_batch_repeats_actions_as_one_env_does(spec: Path) -> None:
    """DeepMind Control's tasks at their own action repeat (4, 8...): each step() sums the repeated steps' rewards and
    ends where the episode ends, in a batch as alone."""
    loaded = load_spec(spec)
    assert loaded.spec.action_repeat > 1
    counts = differential(loaded, 1000 // loaded.spec.action_repeat + 5, repeat=loaded.spec.action_repeat)
    assert counts["ended"] > 0 and counts["raised"] == 0 and counts["errors"] == 0


#: a state that passes float32's range in the third of three repeated steps, after two rewarded ones
REPEATED_OVERFLOW = """\
id: RepeatedOverflow-v0
state:
  x: {init: "uniform(1, 2)"}
actions:
  discrete: [{grow: 1}, {grow: 2}]
dynamics:
  update:
    x: "x * 1e15 * grow"
reward: 1.0
max_steps: 40
on_fault: terminate
"""


def test_a_fault_in_a_repeated_step_ends_it_without_reward_in_a_batch_as_alone() -> None:
    """One env's step that faults in its third repeat returns no reward (the two rewarded repeats before included):
    a batch's does the same."""
    counts = differential(load_spec_text(REPEATED_OVERFLOW, name="repeated.yaml"), 12, repeat=3)
    assert counts["errors"] >= N and counts["raised"] == 0, counts


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP], ids=lambda m: m.name)
def test_a_batch_of_one_steps_as_one_env_does(mode: AutoresetMode) -> None:
    """A batch of one steps its env by its lane, which repeats the action itself: the same rewards, endings (a step
    limit that is no multiple of the repeat) and faults as one env."""
    assert differential(load_spec_text(FEATURES, name="features.yaml"), 200, mode=mode, n=1)["ended"] > 0
    assert differential(load_spec_text(REPEATED_OVERFLOW, name="repeated.yaml"), 12, mode=mode, repeat=3, n=1)["errors"]
    assert differential(load_spec(SPECS / "dmc" / "cartpole_swingup.yaml"), 340, mode=mode, repeat=3, n=1)["ended"]


def test_every_function_of_the_language_gives_one_envs_value_in_a_batch() -> None:
    """tan, exp, atan2...: numpy's loops may differ from Python's math in the last bit (AVX-512's); a batch computes Python's."""
    counts = differential(load_spec_text(CURVES, name="curves.yaml"), 300)
    assert counts["ended"] > N and counts["errors"] == 0


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP], ids=lambda m: m.name)
def test_episodes_end_alike_with_either_autoreset(mode: AutoresetMode) -> None:
    counts = differential(load_spec_text(FEATURES, name="features.yaml"), 200, mode=mode)
    assert counts["ended"] > N


@pytest.mark.parametrize("case", HOSTILE)
def test_a_fault_raised_in_a_batch_is_its_envs_fault_named_by_its_index(case: str, tmp_path: Path) -> None:
    assert differential(hostile(case, "raise", tmp_path), 300, nan_rate=0.03)["raised"] == 1


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP], ids=lambda m: m.name)
@pytest.mark.parametrize("case", HOSTILE)
def test_a_fault_that_terminates_ends_the_same_episode_in_a_batch(
    case: str, mode: AutoresetMode, tmp_path: Path
) -> None:
    counts = differential(hostile(case, "terminate", tmp_path), 300, nan_rate=0.03, mode=mode)
    assert counts["errors"] >= 2 and counts["raised"] == 0, counts


NAN_TARGETS = ["features", *(p for p in BUNDLED if "continuous" in p.read_text() or p.parent.name == "mujoco")]


@pytest.mark.parametrize("on_fault", ["raise", "terminate"])
@pytest.mark.parametrize("spec", NAN_TARGETS, ids=lambda s: getattr(s, "stem", s))
def test_a_nan_action_is_the_same_fault_in_one_env_and_in_a_batch(spec: Any, on_fault: str) -> None:
    loaded = load_spec_text(FEATURES, name="features.yaml") if spec == "features" else load_spec(spec)
    counts = differential(with_fault_policy(loaded, on_fault), 80, nan_rate=0.03)
    assert counts["raised"] == 1 if on_fault == "raise" else counts["errors"] >= 1, counts


def test_a_fault_at_reset_names_the_env_whose_draw_faulted() -> None:
    """An initial state past float32 (about one draw in six here) is the reset fault one env raises, named by its index."""
    text = OVERFLOW.replace('x: {init: "uniform(1, 2)"}', 'x: {init: "uniform(0, 4) * 1e38"}')
    loaded = load_spec_text(text, name="overflow.yaml")
    faults = []
    for i in range(12):
        try:
            VisualEnv(loaded, render=False).reset(seed=SEED + i)
        except StepError as err:
            faults.append((i, str(err)))
    assert faults and faults[0][0] > 0 and "is too large for the float32 observation" in faults[0][1]
    with pytest.raises(StepError) as raised:
        BatchedVectorEnv(loaded, 12, render=False).reset(seed=SEED)
    assert str(raised.value) == "env {}: {}".format(*faults[0]) and raised.value.env == faults[0][0]


def test_a_fault_in_a_worker_names_its_env_in_the_whole_vector_env(tmp_path: Path) -> None:
    """Several batches as one vector env (worker processes): env 3 is env 1 of the second worker's batch, and its fault says env 3."""
    import visualenv

    path = tmp_path / "overflow.yaml"
    path.write_text(OVERFLOW.replace('"uniform(1, 2)"', "1.0"))
    single = VisualEnv(path, render=False)
    single.reset(seed=0)
    vec = visualenv.make_vec(str(path), 4, batched=True, workers=2, render=False)
    try:
        vec.reset(seed=0)
        with pytest.raises(StepError) as raised:
            for _ in range(10):
                vec.step(np.array([0, 0, 0, 1]))
        with pytest.raises(StepError) as alone:
            for _ in range(10):
                single.step(1)
        assert str(raised.value) == f"env 3: {alone.value}" and raised.value.env == 3
    finally:
        vec.close()


def test_a_batch_computes_each_function_as_python_does_and_notes_where_python_raises() -> None:
    """The batch's function table gives Python's values to the bit (numpy's own loops are not used where they differ
    on this CPU); on edge values (0, inf, NaN, huge...) each value Python raises on is noted, so that the batch steps
    that env alone, and each one it does not note is Python's."""
    table = vector_functions()
    rng = np.random.default_rng(3)
    domains = {"asin": (-1, 1), "acos": (-1, 1), "log": (1e-3, 1e3), "log1p": (-0.999, 1e3), "sqrt": (0, 100)}
    arity = {"clip": 3, "min": 2, "max": 2, "hypot": 2, "atan2": 2, "pow": 2, "/": 2, "//": 2, "%": 2}
    python = {name: f.impl for name, f in FUNCTIONS.items() if not f.random}
    python.update({"pow": power, "/": operator.truediv, "//": operator.floordiv, "%": operator.mod})
    vector = {
        **table,
        **{symbol: OPERATORS[op] for symbol, op in (("/", ast.Div), ("//", ast.FloorDiv), ("%", ast.Mod))},
    }
    for name, scalar in python.items():
        n = arity.get(name, 1)
        args = [rng.uniform(*domains.get(name, (0.01, 10) if name == "pow" else (-5, 5)), 300) for _ in range(n)]
        exact = [scalar(*values) for values in zip(*(a.tolist() for a in args))]  # type: ignore[misc]
        assert np.asarray(vector[name](*args), dtype=np.float64).tolist() == exact, name
        edges = [0.0, -0.0, 0.5, -1.0, 2.0, 1e308, -1e308, 1e-320, math.inf, -math.inf, math.nan]
        for values in itertools.product(edges, repeat=n):
            try:
                expected: float | None = float(scalar(*values))  # type: ignore[misc]
            except (ArithmeticError, ValueError):
                expected = None
            with float_errors() as met:
                got = float(np.asarray(vector[name](*(np.array([0.5, v]) for v in values)), dtype=np.float64)[1])
            where = f"{name}{values}"
            assert met or expected is not None, f"{where} raises in Python: the batch must note it"
            if not met:
                assert got == expected or (math.isnan(got) and math.isnan(expected)), (
                    f"{where}: {got} != Python's {expected}"
                )  # type: ignore[arg-type]
    with float_errors() as met:
        table["log"](np.array([0.5, 2.0]))
        table["floor"](np.array([0.5, -2.5]))
        OPERATORS[ast.Div](np.array([1.0, 2.0]), np.array([0.5, -3.0]))
    assert not met
