"""The compiler and the state-only env: spaces, dynamics, rewards, outcomes, API."""

import pickle
import textwrap

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import visualenv
from visualenv import SpecError, VisualEnv, load_spec_text
from visualenv.errors import StepError


def env_from(text: str, name: str = "t.yaml", **kwargs) -> VisualEnv:
    return VisualEnv(load_spec_text(textwrap.dedent(text), name), render=False, **kwargs)


WALKER = """
id: Walker-v0
params: {speed: 0.5, goal: 2.0}
state:
  x: {init: 0.0}
  tag: {init: "uniform(0, 1)", observe: false}
actions:
  discrete:
    - {}
    - {move: speed}
    - {move: -speed}
dynamics:
  update: {x: x + move}
reward: -0.1
outcomes:
  home:  {when: x >= goal, reward: 10, success: true}
  lost:  {when: x < -1, reward: -5}
  halfway: {when: x >= 1, reward: 1, end: none}
max_steps: 10
"""


def test_spaces_and_observation_order():
    env = env_from(WALKER)
    assert env.action_space == gym.spaces.Discrete(3)
    assert env.observation_space.shape == (1,)  # 'tag' is not observed
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and obs.tolist() == [0.0]
    assert set(info["state"]) == {"x", "tag"}


def test_discrete_inputs_rewards_and_success_outcome():
    env = env_from(WALKER)
    env.reset(seed=0)
    rewards = []
    for _ in range(4):
        _, r, terminated, truncated, info = env.step(1)
        rewards.append(r)
    assert rewards == pytest.approx([-0.1, 0.9, -0.1, 9.9])  # milestone once at x=1, goal at x=2
    assert terminated and not truncated
    assert info["outcome"] == "home" and info["is_success"] and info["milestones"] == ["halfway"]


def test_several_milestones_are_named_and_rewarded_in_spec_order():
    env = env_from("""
        id: Steps-v0
        state:
          x: {init: 0.0}
        actions:
          discrete:
            - {move: 1}
        dynamics:
          update: {x: x + move}
        reward: 0
        outcomes:
          first:  {when: x >= 1, reward: 1, end: none}
          second: {when: x >= 3, reward: 10, end: none, success: true}
        max_steps: 10
    """)
    env.reset(seed=0)
    seen = []
    for _ in range(3):
        _, r, _, _, info = env.step(0)
        seen.append((r, info["milestones"], info["is_success"]))
    assert seen == [(1.0, ["first"], False), (0.0, ["first"], False), (10.0, ["first", "second"], True)]


def test_failure_outcome_and_noop_action():
    env = env_from(WALKER)
    env.reset(seed=0)
    _, r, terminated, _, info = env.step(0)
    assert r == pytest.approx(-0.1) and not terminated and info["state"]["x"] == 0.0
    for _ in range(3):
        _, r, terminated, _, info = env.step(2)
    assert terminated and info["outcome"] == "lost" and r == pytest.approx(-5.1) and not info["is_success"]


def test_max_steps_truncates():
    env = env_from(WALKER)
    env.reset(seed=0)
    for i in range(10):
        _, _, terminated, truncated, info = env.step(0)
        assert not terminated
        assert truncated == (i == 9)
    assert info["outcome"] == "max_steps"


def test_truncate_outcome_with_reward():
    env = env_from(
        WALKER.replace(
            "halfway: {when: x >= 1, reward: 1, end: none}", "survived: {when: steps >= 3, reward: 10, end: truncate}"
        )
    )
    env.reset(seed=0)
    for _ in range(3):
        _, r, terminated, truncated, info = env.step(0)
    assert truncated and not terminated and info["outcome"] == "survived" and r == pytest.approx(9.9)


def test_reset_options_set_initial_state():
    env = env_from(WALKER)
    _, info = env.reset(seed=1, options={"state": {"x": 1.5}})
    assert info["state"]["x"] == 1.5
    with pytest.raises(KeyError, match="unknown variable 'y'"):
        env.reset(options={"state": {"y": 1}})


def test_seeded_random_init_is_reproducible():
    env = env_from(WALKER)
    a = env.reset(seed=5)[1]["state"]["tag"]
    b = env.reset(seed=5)[1]["state"]["tag"]
    c = env.reset(seed=6)[1]["state"]["tag"]
    assert a == b != c and 0 <= a < 1


def test_continuous_actions_are_clipped_to_bounds():
    env = env_from("""
        id: Push-v0
        state: {v: {init: 0}}
        actions: {continuous: {thrust: {low: -1, high: 2}, turn: {low: -0.5, high: 0.5}}}
        dynamics: {update: {v: v + thrust + turn}}
    """)
    assert env.action_space == gym.spaces.Box(np.array([-1, -0.5], np.float32), np.array([2, 0.5], np.float32))
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([5.0, -3.0]))
    assert info["state"]["v"] == pytest.approx(1.5)


def test_params_are_expressions_and_can_be_overridden():
    env = env_from(WALKER.replace("{speed: 0.5, goal: 2.0}", "{goal: 2.0, speed: goal / 4}"))
    env.reset(seed=0)
    assert env.step(1)[4]["state"]["x"] == pytest.approx(0.5)
    env2 = env_from(WALKER, params={"speed": 2.0})
    env2.reset(seed=0)
    assert env2.step(1)[4]["state"]["x"] == 2.0
    with pytest.raises(SpecError, match="unknown parameter override 'sped'"):
        env_from(WALKER, params={"sped": 1})


def test_params_can_use_dt_and_max_steps():
    # a walker that covers `goal` in max_steps steps: speed is derived from the episode length
    env = env_from(WALKER.replace("{speed: 0.5, goal: 2.0}", "{goal: 2.0, speed: goal / max_steps + 0 * dt}"))
    env.reset(seed=0)
    assert env.step(1)[4]["state"]["x"] == pytest.approx(0.2)


def test_forward_references_are_explained():
    with pytest.raises(SpecError, match="'goal' is defined later in params"):
        env_from(WALKER.replace("speed: 0.5", "speed: goal / 4"))
    with pytest.raises(SpecError, match="'b' is defined later in dynamics.let"):
        env_from(WALKER.replace("update: {x: x + move}", "let: {a: b, b: a}\n  update: {x: x + a}"))


def test_let_reads_old_state_and_updates_are_simultaneous():
    env = env_from("""
        id: Swap-v0
        state: {a: {init: 1}, b: {init: 2}}
        actions: {discrete: [{}]}
        dynamics:
          let: {s: a + b, d: s * 2}
          update: {a: b, b: a + d}
    """)
    env.reset(seed=0)
    assert env.step(0)[4]["state"] == {"a": 2.0, "b": 7.0}


def test_check_env_passes_and_env_pickles():
    env = visualenv.make("specs/visual_cartpole.yaml", render=False)
    check_env(env.unwrapped, skip_render_check=True)
    clone = pickle.loads(pickle.dumps(env.unwrapped))
    a = env.reset(seed=3)[0]
    b = clone.reset(seed=3)[0]
    np.testing.assert_array_equal(a, b)


def test_gymnasium_make_with_bundled_id():
    env = gym.make("visualenv/VisualCartPole-v0", render=False)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4,)
    assert visualenv.make("VisualCartPole-v0", render=False).observation_space.shape == (4,)


def test_yaml_and_toml_specs_compile_to_the_same_env(tmp_path):
    toml = tmp_path / "walker.toml"
    toml.write_text(
        textwrap.dedent("""
        id = "Walker-v0"
        reward = -0.1
        max_steps = 10

        [params]
        speed = 0.5
        goal = 2.0

        [state]
        x = { init = 0.0 }
        tag = { init = "uniform(0, 1)", observe = false }

        [actions]
        discrete = [{}, { move = "speed" }, { move = "-speed" }]

        [dynamics.update]
        x = "x + move"

        [outcomes.home]
        when = "x >= goal"
        reward = 10
        success = true

        [outcomes.lost]
        when = "x < -1"
        reward = -5

        [outcomes.halfway]
        when = "x >= 1"
        reward = 1
        end = "none"
    """)
    )
    yaml_env, toml_env = env_from(WALKER), VisualEnv(visualenv.load_spec(toml), render=False)
    for env in (yaml_env, toml_env):
        env.reset(seed=2)
    for action in [1, 1, 0, 2, 1, 1, 1]:
        a, b = yaml_env.step(action), toml_env.step(action)
        assert a[1:] == b[1:]


def test_toml_errors_are_located(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('id = "Bad-v0"\n\n[state]\nx = { init = "sin(y)" }\n\n[actions]\ndiscrete = [{}]\n')
    with pytest.raises(SpecError) as err:
        visualenv.compile_spec(visualenv.load_spec(path))
    assert str(err.value).startswith(f"{path}:4:") and "unknown name 'y'" in str(err.value)


def test_all_problems_are_reported_at_once():
    with pytest.raises(SpecError) as err:
        env_from("""
            id: Many-v0
            state: {x: {init: "sin(q)"}}
            actions: {discrete: [{f: "cos(w)"}]}
            dynamics: {update: {x: x + f + zz}}
            reward: "x > 1"
            outcomes: {o: {when: x + 1}}
        """)
    lines = str(err.value).splitlines()
    assert len(lines) == 5
    assert "unknown name 'q'" in lines[0] and "unknown name 'w'" in lines[1] and "unknown name 'zz'" in lines[2]
    assert "expected a number, got a condition" in lines[3]
    assert "expected a condition (true/false), got a number" in lines[4]


def test_python_dynamics_escape_hatch():
    env = env_from(
        """
        id: Hook-v0
        params: {gain: 3}
        state: {x: {init: 0}}
        actions: {discrete: [{push: 1}]}
        dynamics: {python: "tests.fixtures.dynamics_hook:drift"}
    """,
        trust_code=True,
    )
    env.reset(seed=0)
    assert env.step(0)[4]["state"]["x"] == 3.0


@pytest.mark.parametrize(
    "function, message",
    [
        ("returns_none", "the function returned NoneType, expected a dict of new state values (state: x)"),
        ("returns_text", "the function returned x='abc', expected a number"),
        ("returns_a_typo", "the function returned 'xx', which is not state (did you mean 'x'?"),
        ("one_argument", "the function raised TypeError: one_argument() takes 1 positional argument but 4 were given"),
    ],
)
def test_python_dynamics_mistakes_are_located_faults(function, message):
    env = env_from(
        f"""
        id: Hook-v0
        state: {{x: {{init: 0}}}}
        actions: {{discrete: [{{push: 1}}]}}
        dynamics: {{python: "tests.fixtures.dynamics_hook:{function}"}}
    """,
        trust_code=True,
    )
    env.reset(seed=0)
    with pytest.raises(StepError) as info:
        env.step(0)
    assert f"dynamics.python = 'tests.fixtures.dynamics_hook:{function}': {message}" in str(info.value)
    assert "(step 0; values: x=0" in str(info.value)


def test_python_dynamics_values_become_floats():
    env = env_from(
        """
        id: Hook-v0
        state: {x: {init: 0}}
        actions: {discrete: [{push: 1}]}
        dynamics: {python: "tests.fixtures.dynamics_hook:keeps_ints"}
    """,
        trust_code=True,
    )
    env.reset(seed=0)
    x = env.step(0)[4]["state"]["x"]
    assert x == 2.0 and type(x) is float


def test_spec_without_observation_is_state_only_even_when_render_requested():
    with pytest.raises(SpecError, match="needs an 'observation'"):
        VisualEnv(load_spec_text(WALKER, "t.yaml"), render=True)


def test_conditional_vector_binding_gives_each_element():
    env = env_from("""
        id: Bind-v0
        scene: {objects: {B: {primitive: cube}}}
        state: {x: {init: 0.5}}
        actions: {discrete: [{dx: -1}]}
        dynamics: {update: {x: x + dx}}
        actors: {B: {location: "[x, 0, 1] if x > 0 else [0, x, 2]", scale: 2}}
    """)
    env.reset(seed=0)
    assert env.binding_values() == (0.5, 0.0, 1.0, 2.0, 2.0, 2.0)
    env.step(0)
    assert env.binding_values() == (0.0, -0.5, 2.0, 2.0, 2.0, 2.0)


@pytest.mark.parametrize("name", ["goalie_randomized.yaml", "lunar_landing.yaml", "dmc/finger_spin.yaml"])
def test_the_render_plan_holds_render_types_only_and_is_built_once(name):
    """Program.render_plan() converts the spec's models into render/plan.py's dataclasses, once."""
    import dataclasses
    from pathlib import Path

    from pydantic import BaseModel

    from visualenv.compiler.program import compile_spec
    from visualenv.spec import load_spec

    program = compile_spec(load_spec(Path(visualenv.__file__).parent / "specs" / name))
    plan = program.render_plan()
    assert program.render_plan() is plan

    def models(value) -> list:
        if isinstance(value, BaseModel):
            return [value]
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            return [m for f in dataclasses.fields(value) for m in models(getattr(value, f.name))]
        if isinstance(value, dict):
            return [m for v in value.values() for m in models(v)]
        if isinstance(value, (list, tuple)):
            return [m for v in value for m in models(v)]
        return []

    assert models(plan) == [] and plan.views
