"""A spec's ``dynamics.python`` is imported only with the caller's consent (``trust_code=True``): make, gymnasium.make,
register, the batch and its worker processes (docs/security.md). No Blender: the probe spec is state-only."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

import visualenv
from visualenv.compiler import compile_spec
from visualenv.env import registration
from visualenv.env.batch import make_batched
from visualenv.errors import SpecError
from visualenv.spec import load_spec, load_spec_text
from tests.fixtures.hostile_code import hostile_spec


@pytest.fixture
def probe(tmp_path, monkeypatch):
    return hostile_spec(tmp_path, monkeypatch)


@pytest.fixture
def clean_registry():
    """Ids registered by a test are forgotten after it."""
    before, trusted, names = dict(registration._REGISTERED), set(registration._TRUSTED), set(gym.registry)
    yield
    registration._REGISTERED.clear()
    registration._REGISTERED.update(before)
    registration._TRUSTED.clear()
    registration._TRUSTED.update(trusted)
    for name in set(gym.registry) - names:
        del gym.registry[name]


def refused(probe, make) -> str:
    """The SpecError `make` raises, checked to be the consent error at the spec's dynamics.python line."""
    with pytest.raises(SpecError) as info:
        make()
    message = str(info.value)
    assert f"{probe.path}:5:" in message and "dynamics.python" in message, message
    assert f"imports the module '{probe.module}'" in message and "calls its 'step'" in message
    assert "--trust-code" in message and "trust_code=True" in message
    assert not probe.imported
    return message


def test_make_imports_nothing_without_consent_and_runs_with_it(probe):
    refused(probe, lambda: visualenv.make(probe.path))
    refused(probe, lambda: visualenv.VisualEnv(probe.path))
    program = compile_spec(load_spec(probe.path))  # compiling checks the reference's form, imports nothing
    assert not probe.imported
    refused(probe, lambda: visualenv.VisualEnv(program))
    env = visualenv.make(probe.path, trust_code=True)
    assert probe.imported
    env.reset(seed=0)
    assert env.step(0)[4]["state"]["x"] == 1.0
    again = env.spec.make()  # the EnvSpec carries the consent: check_env makes the env again from it
    again.reset(seed=0)
    copy = pickle.loads(pickle.dumps(env))  # so does a pickled env
    assert copy.step(1)[4]["state"]["x"] == 0.0


def test_gymnasium_make_needs_consent_from_make_or_from_register(probe, clean_registry):
    assert visualenv.register(probe.path) == [f"visualenv/{probe.env_id}"]  # registering reads the spec as data
    refused(probe, lambda: gym.make(f"visualenv/{probe.env_id}"))
    gym.make(f"visualenv/{probe.env_id}", trust_code=True).reset(seed=0)
    assert probe.imported
    visualenv.register(probe.path, trust_code=True)
    env = gym.make(f"visualenv/{probe.env_id}")
    env.reset(seed=0)
    assert env.step(0)[4]["state"]["x"] == 1.0
    visualenv.register_bundled()  # registering the others again keeps the consent given
    assert gym.spec(f"visualenv/{probe.env_id}").kwargs["trust_code"] is True
    visualenv.register(probe.path)  # and registering without it takes it back
    assert "trust_code" not in gym.spec(f"visualenv/{probe.env_id}").kwargs


def test_a_batch_needs_consent_and_carries_it_to_its_workers(probe):
    refused(probe, lambda: make_batched(str(probe.path), 2, render=False))
    refused(probe, lambda: visualenv.make_vec(str(probe.path), 2, batched=True, workers=2, render=False))
    batch = make_batched(str(probe.path), 2, render=False, trust_code=True)
    batch.reset(seed=0)
    assert list(batch.step(np.array([0, 1]))[4]["state"]["x"]) == [1.0, -1.0]
    batch.close()
    vec = visualenv.make_vec(str(probe.path), 2, batched=True, workers=2, render=False, trust_code=True)
    try:
        vec.reset(seed=0)
        assert list(vec.step(np.array([0, 1]))[4]["state"]["x"]) == [1.0, -1.0]
    finally:
        vec.close()


def test_per_process_vector_envs_carry_the_consent_to_their_workers(probe):
    vec = visualenv.make_vec(str(probe.path), 2, render=False, trust_code=True)
    try:
        vec.reset(seed=0)
        assert list(vec.step(np.array([0, 1]))[4]["state"]["x"]) == [1.0, -1.0]
    finally:
        vec.close()


@pytest.mark.parametrize(
    "reference, problem",
    [
        ("a..b:step", "'a..b:step' has an empty name"),
        ("os.class:step", "'class' in 'os.class:step' is a Python keyword"),
        ("1os:step", "expected 'module:function'"),
    ],
)
def test_a_malformed_reference_is_located_without_importing(reference, problem):
    text = (
        f'id: R-v0\nstate: {{x: {{init: 0}}}}\nactions: {{discrete: [{{u: 1}}]}}\ndynamics: {{python: "{reference}"}}\n'
    )
    with pytest.raises(SpecError, match=f"r.yaml:4:.*dynamics.python: .*{problem}"):
        compile_spec(load_spec_text(text, name="r.yaml"))


def test_a_spec_without_python_dynamics_needs_no_consent():
    env = visualenv.make("VisualCartPole-v0", render=False)
    env.reset(seed=0)
    assert "trust_code" not in env.spec.kwargs


def test_gymnasium_make_vec_takes_the_consent_as_an_env_option(probe, clean_registry):
    (env_id,) = visualenv.register(probe.path)
    for mode in ("vector_entry_point", "sync"):
        refused(probe, lambda mode=mode: gym.make_vec(env_id, 2, vectorization_mode=mode))
    vec = gym.make_vec(env_id, 2, vectorization_mode="vector_entry_point", trust_code=True)
    vec.reset(seed=0)
    assert list(vec.step(np.array([0, 1]))[4]["state"]["x"]) == [1.0, -1.0]


def test_sb3_subprocess_workers_carry_the_consent(probe):
    pytest.importorskip("stable_baselines3")
    vec = visualenv.make_sb3_vec(str(probe.path), 2, render=False, frame_stack=1, trust_code=True)
    try:
        vec.reset()
        assert vec.step(np.array([0, 1]))[0][:, 0].tolist() == [1.0, -1.0]  # each worker stepped the module's step
    finally:
        vec.close()


@pytest.mark.parametrize("value", ["false", 1])
def test_the_consent_is_true_or_false_not_any_truthy_value(probe, value):
    with pytest.raises(SpecError, match="trust_code"):
        visualenv.make(probe.path, trust_code=value)
    with pytest.raises(TypeError, match="trust_code must be True or False"):
        compile_spec(load_spec(probe.path), trust_code=value)
    assert not probe.imported
