"""A policy file is checked against its weights before its network is built (visualenv/train/policy_check.py): a
policy.json that asks for a huge network, weights that are integers, NaN, infinite or of another shape are refused
with an error that names the file and the tensor or field, in a second and without allocating what they ask for.
The hostile files are made here from a small real policy (tests/fixtures/policy_files.py)."""

import json
import math
import resource
import struct
import time
from pathlib import Path

import pytest

from tests.fixtures.policy_files import (
    as_int32,
    copy_of,
    huge_network,
    rewrite_meta,
    rewrite_weights,
    small_policy,
    transposed,
    with_value,
)
from visualenv.compat.sb3 import constructor_parameters
from visualenv.train.model_files import export_policy, load_model
from visualenv.train.policy_check import MAX_LIST, MAX_SPACE_ELEMENTS, PARAMETERS_VARIABLE
from visualenv.train.policy_kinds import PolicyFileError

torch = pytest.importorskip("torch")
RESULTS = Path(__file__).resolve().parents[2] / "results"


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    return small_policy(tmp_path_factory.mktemp("small"))


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _lying_header(weights):
    """A safetensors header that claims a 15,000 x 15,000 tensor, with 64 bytes of data."""
    header = json.dumps(
        {"action_net.weight": {"dtype": "F32", "shape": [15000, 15000], "data_offsets": [0, 9 * 10**8]}}
    )
    weights.write_bytes(struct.pack("<Q", len(header)) + header.encode() + bytes(64))
    return weights


HOSTILE = {
    "huge net_arch": (
        lambda w: rewrite_meta(w, huge_network),
        r"policy.safetensors does not hold the network policy.json describes \(450,[0-9,]+ parameters; the file holds "
        r"251\): tensor 'mlp_extractor.policy_net.0.weight' is \[8, 4\] in the file and \[15000, 4\] in the network",
    ),
    "a layer per entry": (
        lambda w: rewrite_meta(w, lambda m: m["arguments"].update(net_arch=[1] * 100_000)),
        rf"policy.json: arguments.net_arch: 100000 entries; a policy file's network takes at most {MAX_LIST}",
    ),
    "huge observation": (
        lambda w: rewrite_meta(w, lambda m: m["observation_space"].update(shape=[100_000, 100_000])),
        rf"policy.json: observation_space: 10,000,000,000 numbers per step; .* at most {MAX_SPACE_ELEMENTS:,}",
    ),
    "NaN": (
        lambda w: rewrite_weights(w, with_value("action_net.weight", math.nan)),
        r"policy.safetensors: tensor 'action_net.weight' holds 1 NaN or infinite values \(of 16\)",
    ),
    "infinity": (
        lambda w: rewrite_weights(w, with_value("value_net.bias", -math.inf)),
        r"policy.safetensors: tensor 'value_net.bias' holds 1 NaN or infinite values",
    ),
    "int32": (
        lambda w: rewrite_weights(w, as_int32),
        r"policy.safetensors: tensor '[a-z_.0-9]+' is I32: a policy's weights are floating point",
    ),
    "wrong shape": (
        lambda w: rewrite_weights(w, transposed("mlp_extractor.value_net.0.weight")),
        r"tensor 'mlp_extractor.value_net.0.weight' is \[4, 8\] in the file and \[8, 4\] in the network",
    ),
    "missing tensor": (
        lambda w: rewrite_weights(w, lambda t: {k: v for k, v in t.items() if k != "value_net.weight"}),
        r"tensor 'value_net.weight' \(\[1, 8\]\) is missing",
    ),
    "extra tensor": (
        lambda w: rewrite_weights(w, lambda t: {**t, "backdoor": torch.zeros(3)}),
        r"tensor 'backdoor' is not one of the network's",
    ),
    "a header that lies": (
        lambda w: _lying_header(w),
        r"policy.safetensors: not a safetensors file \(.*incomplete metadata",
    ),
    "not safetensors": (
        lambda w: w.write_bytes(b"\xff" * 64) and w,
        r"policy.safetensors: not a safetensors file",
    ),
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_a_hostile_policy_file_is_refused_before_its_network_is_built(policy, tmp_path, case):
    make, message = HOSTILE[case]
    weights = copy_of(policy, tmp_path)
    make(weights)
    before, started = _peak_rss_mb(), time.perf_counter()
    with pytest.raises(PolicyFileError, match=message) as refused:
        load_model(weights)
    assert time.perf_counter() - started < 10 and _peak_rss_mb() - before < 500  # nothing of its size was allocated
    assert str(tmp_path) in str(refused.value)  # located: the file's path
    with pytest.raises(PolicyFileError, match=message):
        export_policy(weights, tmp_path / "out.safetensors")
    assert not (tmp_path / "out.safetensors").exists() and not (tmp_path / "out.json").exists()


def test_the_parameter_limit_is_checked_and_raised_by_its_variable(policy, monkeypatch):
    monkeypatch.setenv(PARAMETERS_VARIABLE, "100")
    with pytest.raises(
        PolicyFileError, match=rf"describes a network of 251 parameters, above the 100 .*{PARAMETERS_VARIABLE}"
    ):
        load_model(policy)
    monkeypatch.setenv(PARAMETERS_VARIABLE, "1_000")
    assert load_model(policy).action_space.n == 2
    monkeypatch.setenv(PARAMETERS_VARIABLE, "many")
    with pytest.raises(PolicyFileError, match=f"{PARAMETERS_VARIABLE}='many': expected a count"):
        load_model(policy)


def test_a_sound_policy_file_still_loads_and_exports_once_then_only_with_force(policy, tmp_path):
    from visualenv.errors import VisualEnvError

    out = tmp_path / "again.safetensors"
    assert export_policy(policy, out, half=False) == out
    with pytest.raises(VisualEnvError, match=r"again.safetensors and .*again.json already exist: pass --force"):
        export_policy(policy, out)
    out.with_suffix(".json").write_text("{}")
    out.unlink()  # half a pair is refused too
    with pytest.raises(VisualEnvError, match=r"again.json already exists: pass --force"):
        export_policy(policy, out)
    export_policy(policy, out, force=True)
    assert json.loads(out.with_suffix(".json").read_text())["format"] == "visualenv-policy"
    assert load_model(out).action_space.n == 2


def test_export_refuses_a_trusted_model_with_weights_that_are_not_finite(policy, tmp_path):
    policy_object = load_model(policy)
    with torch.no_grad():
        policy_object.action_net.bias[0] = math.nan
    torch.save(
        {
            "state_dict": policy_object.state_dict(),
            "data": constructor_parameters(policy_object),
            "policy_class": "stable_baselines3.common.policies.ActorCriticPolicy",
        },
        tmp_path / "model.pt",
    )
    with pytest.raises(PolicyFileError, match=r"model.pt: tensor 'action_net.bias' holds 1 NaN or infinite values"):
        export_policy(tmp_path / "model.pt", tmp_path / "out.safetensors", trust_pickle=True)
    assert not (tmp_path / "out.safetensors").exists()


def test_distill_refuses_a_pickle_with_what_it_takes(tmp_path):
    from visualenv.train.distill import DistillConfig, distill
    from visualenv.train.model_files import PickleRefused

    (tmp_path / "teacher.zip").write_bytes(b"PK")
    with pytest.raises(PickleRefused) as refused:
        distill(DistillConfig(spec="VisualCartPole-v0", teacher=str(tmp_path / "teacher.zip")), tmp_path / "runs")
    text = str(refused.value)
    assert "`visualenv distill` takes policy files only" in text and "visualenv export-policy --trust-pickle" in text
    assert "pass --trust-pickle" not in text and "trust_pickle=True" not in text
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("folder", sorted(p.name for p in RESULTS.glob("*") if (p / "policy.safetensors").is_file()))
def test_every_shipped_agent_passes_the_checks(folder):
    """Each shipped policy file (read only) fits the network its policy.json describes, within the limits."""
    weights = RESULTS / folder / "policy.safetensors"
    meta = json.loads(weights.with_suffix(".json").read_text())
    if meta["backend"] == "rllib":
        pytest.importorskip("ray.rllib")
    assert load_model(weights).action_space is not None
