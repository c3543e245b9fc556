"""Policy files are data (policy.safetensors + policy.json): they load without unpickling anything, rebuild the same
network, and name classes only from visualenv's fixed lists. Pickle-based models load only when trusted.

The hostile files here are real: each is shown to run its code (it writes a marker file) when the usual unsafe loader
reads it, in a process of its own, before `visualenv eval`, `play` and `export-policy` are shown to refuse it with
the marker left unwritten.
"""

import base64
import json
import os
import pickle
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from gymnasium import spaces

from visualenv.cli import main
from visualenv.train.model_files import PickleRefused, load_model, pretrained_model, save_policy
from visualenv.train.policy_format import read_meta, space_from_data, space_to_data, write_policy
from visualenv.train.policy_kinds import PolicyFileError, sb3_policies

torch = pytest.importorskip("torch")
REPO = Path(__file__).resolve().parents[2]
SHIPPED = [
    "Goalie-v0",
    "Hover2D-v0",
    "LunarLanding-v0",
    "VisualCartPole-v0",
    "VisualInvertedPendulum-v0",
    "DMC-cartpole-swingup-v0",
]


class Payload:
    """Pickles as a call that writes `marker`: what a hostile model file carries (here harmless, and visible)."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return exec, (f"open({self.marker!r}, 'w').write('code ran')",)


# -- the format -------------------------------------------------------------------------------------------------------


IMAGE, STATE = spaces.Box(0, 255, (4, 40, 40), np.uint8), spaces.Box(-np.inf, np.inf, (5,), np.float32)
CAMERAS = spaces.Dict(
    {"front": spaces.Box(0, 255, (3, 40, 40), np.uint8), "state": spaces.Box(-1.0, 2.0, (3,), np.float64)}
)
KINDS = [  # every SB3 policy kind the format takes, on spaces it fits
    ("stable_baselines3.common.policies.ActorCriticPolicy", STATE, spaces.Discrete(3)),
    ("stable_baselines3.common.policies.ActorCriticCnnPolicy", IMAGE, spaces.Box(-1.0, 1.0, (2,), np.float32)),
    ("stable_baselines3.common.policies.MultiInputActorCriticPolicy", CAMERAS, spaces.MultiDiscrete([3, 2])),
    ("stable_baselines3.dqn.policies.DQNPolicy", STATE, spaces.Discrete(4)),
    ("stable_baselines3.dqn.policies.CnnPolicy", IMAGE, spaces.Discrete(2)),
    ("stable_baselines3.dqn.policies.MultiInputPolicy", CAMERAS, spaces.Discrete(2)),
    ("stable_baselines3.sac.policies.SACPolicy", STATE, spaces.Box(-2.0, 2.0, (1,), np.float32)),
    ("stable_baselines3.sac.policies.CnnPolicy", IMAGE, spaces.Box(-1.0, 1.0, (2,), np.float32)),
    ("stable_baselines3.sac.policies.MultiInputPolicy", CAMERAS, spaces.Box(-1.0, 1.0, (2,), np.float32)),
    ("visualenv.train.drq.DrQSACPolicy", IMAGE, spaces.Box(-1.0, 1.0, (2,), np.float32)),
]


def test_every_sb3_kind_in_the_list_is_covered():
    assert sorted(sb3_policies()) == sorted(kind for kind, _, _ in KINDS)


def _observations(space, n=6):
    space.seed(0)
    batch = [space.sample() for _ in range(n)]
    if isinstance(space, spaces.Dict):
        return {k: np.stack([b[k] for b in batch]) for k in space.spaces}
    return np.stack(batch)


@pytest.mark.parametrize(
    "kind, observation_space, action_space", KINDS, ids=[".".join(k.split(".")[-3::2]) for k, _, _ in KINDS]
)
def test_a_policy_comes_back_as_the_same_network(kind, observation_space, action_space, tmp_path):
    policy = sb3_policies()[kind](observation_space, action_space, lambda _: 0.0, activation_fn=torch.nn.ReLU)
    policy.set_training_mode(False)
    save_policy(policy, tmp_path / "policy.safetensors", half=False)
    back = load_model(tmp_path / "policy.json")  # either file of the pair names it
    assert (
        type(back) is type(policy) and back.observation_space == observation_space and back.action_space == action_space
    )
    want, got = policy.state_dict(), back.state_dict()
    assert want.keys() == got.keys() and all(torch.equal(want[k], got[k]) for k in want)
    obs = _observations(observation_space)
    assert np.array_equal(policy.predict(obs, deterministic=True)[0], back.predict(obs, deterministic=True)[0])
    meta = read_meta(tmp_path / "policy.safetensors")
    assert (
        meta["policy"] == kind and meta["arguments"]["activation_fn"] == "torch.nn.ReLU" and meta["dtype"] == "float32"
    )


def test_float16_weights_are_stored_once_and_read_into_a_float32_network(tmp_path):
    from safetensors import safe_open

    policy = sb3_policies()["stable_baselines3.common.policies.ActorCriticCnnPolicy"](
        IMAGE, spaces.Discrete(2), lambda _: 0.0
    )
    weights = save_policy(policy, tmp_path / "policy.safetensors")
    with safe_open(str(weights), "pt") as f:
        names = list(f.keys())
        assert {f.get_tensor(n).dtype for n in names} == {torch.float16}
    assert not [
        n for n in names if n.startswith(("pi_features_extractor", "vf_features_extractor"))
    ]  # shared: stored once
    back = load_model(weights)
    assert back.pi_features_extractor is back.features_extractor  # and shared again
    for name, value in back.state_dict().items():
        assert value.dtype == torch.float32 and torch.equal(value, policy.state_dict()[name].half().float()), name


def test_spaces_round_trip_through_json():
    cases = [
        STATE,
        IMAGE,
        CAMERAS,
        spaces.Discrete(5, start=-2),
        spaces.MultiDiscrete([2, 3]),
        spaces.MultiBinary(4),
        spaces.Box(np.array([-1.0, -np.inf], np.float32), np.array([1.0, 2.5], np.float32), dtype=np.float32),
    ]
    for space in cases:
        text = json.dumps(space_to_data(space), allow_nan=False)  # strict JSON: infinities as strings
        assert space_from_data(json.loads(text)) == space


def test_loading_a_policy_file_unpickles_nothing(tmp_path, monkeypatch):
    policy = sb3_policies()["stable_baselines3.common.policies.ActorCriticPolicy"](
        STATE, spaces.Discrete(2), lambda _: 0.0
    )
    save_policy(policy, tmp_path / "policy.safetensors")

    def refuse(*args, **kwargs):
        raise AssertionError("something unpickled")

    for module in (pickle, __import__("_pickle")):
        monkeypatch.setattr(module, "Unpickler", refuse)
        monkeypatch.setattr(module, "loads", refuse)
        monkeypatch.setattr(module, "load", refuse)
    monkeypatch.setattr(torch, "load", refuse)
    assert load_model(tmp_path / "policy.safetensors").action_space == spaces.Discrete(2)


@pytest.mark.parametrize(
    "change, message",
    [
        (
            {"policy": "os.system"},
            "policy 'os.system' is not one visualenv builds; allowed: stable_baselines3.common.policies.ActorCriticPolicy",
        ),
        (
            {"arguments": {"activation_fn": "builtins.eval"}},
            "activation_fn 'builtins.eval' is not one visualenv builds; allowed: torch.nn.Tanh",
        ),
        (
            {"arguments": {"features_extractor_class": "my.Extractor"}},
            "allowed: stable_baselines3.common.torch_layers.NatureCNN",
        ),
        ({"arguments": {"optimizer_class": "torch.optim.Adam"}}, "optimizer_class: not arguments of"),
        ({"backend": "pickle"}, "backend 'pickle' is not sb3 or rllib"),
        ({"format_version": 9}, "format_version 9; this visualenv reads version 1"),
        (
            {"observation_space": {"type": "Box", "shape": [5], "dtype": "object", "low": 0, "high": 1}},
            "'object' is not one of uint8",
        ),
        ({"action_space": {"type": "Tuple"}}, "action_space.type: 'Tuple' is not one of Box"),
    ],
)
def test_a_policy_json_names_classes_only_from_the_lists(tmp_path, change, message):
    policy = sb3_policies()["stable_baselines3.common.policies.ActorCriticPolicy"](
        STATE, spaces.Discrete(2), lambda _: 0.0
    )
    save_policy(policy, tmp_path / "policy.safetensors")
    meta = json.loads((tmp_path / "policy.json").read_text())
    for key, value in change.items():
        meta[key] = {**meta[key], **value} if key == "arguments" else value
    (tmp_path / "policy.json").write_text(json.dumps(meta))
    with pytest.raises(PolicyFileError, match=re.escape(message)):
        load_model(tmp_path / "policy.safetensors")
    result = CliRunner().invoke(
        main, ["export-policy", str(tmp_path / "policy.safetensors"), str(tmp_path / "again.safetensors")]
    )
    assert result.exit_code == 1 and message in result.output and not isinstance(result.exception, PolicyFileError)


def test_weights_that_do_not_fit_and_missing_halves_are_clear_errors(tmp_path):
    make = sb3_policies()["stable_baselines3.common.policies.ActorCriticPolicy"]
    save_policy(make(STATE, spaces.Discrete(2), lambda _: 0.0), tmp_path / "a.safetensors")
    save_policy(make(STATE, spaces.Discrete(3), lambda _: 0.0), tmp_path / "b.safetensors")
    (tmp_path / "b.json").replace(tmp_path / "a.json")  # a's weights, b's network
    with pytest.raises(
        PolicyFileError,
        match=r"a.safetensors does not hold the network a.json describes .*action_net.weight. is \[2, 64\] in the file and \[3, 64\]",
    ):
        load_model(tmp_path / "a.safetensors")
    with pytest.raises(PolicyFileError, match=r"b.json does not exist"):
        load_model(tmp_path / "b.safetensors")
    (tmp_path / "a.safetensors").unlink()
    with pytest.raises(PolicyFileError, match=r"a.safetensors does not exist"):
        load_model(tmp_path / "a.json")
    (tmp_path / "config.json").write_text('{"config": {}}')  # a run's config.json passed by mistake
    with pytest.raises(PolicyFileError, match="config.json: not a policy file of visualenv"):
        load_model(tmp_path / "config.json")


def test_a_custom_class_cannot_be_exported_as_data(tmp_path):
    class Custom(torch.nn.Tanh):
        pass

    policy = sb3_policies()["stable_baselines3.common.policies.ActorCriticPolicy"](
        STATE, spaces.Discrete(2), lambda _: 0.0, activation_fn=Custom
    )
    with pytest.raises(PolicyFileError, match="cannot be written as data: a policy file names one of torch.nn.Tanh"):
        write_policy(tmp_path / "policy.safetensors", policy, backend="sb3", algorithm="ppo", half=True)


# -- the shipped agents -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("env_id", SHIPPED)
def test_each_shipped_agent_is_a_float16_policy_file_and_nothing_under_results_is_a_pickle(env_id):
    meta = read_meta(pretrained_model(env_id))
    assert meta["dtype"] == "float16" and meta["backend"] == "sb3" and meta["spec"]["id"] == env_id
    assert meta["frame_stack"] == (
        3 if env_id.startswith("DMC-") else 4
    )  # DrQ's 3 for DeepMind Control, the paper's 4 otherwise
    assert pretrained_model(env_id).name == "policy.safetensors"


def test_pretrained_colon_name_is_an_agent_shipped_beside_the_main_one_and_an_unknown_name_lists_those_there_are():
    from visualenv.errors import VisualEnvError
    from visualenv.viewer.app import load_agent

    folder = REPO / "results" / "DMC-cartpole-swingup-v0"
    assert pretrained_model("DMC-cartpole-swingup-v0", "pretrained:robust") == folder / "robust" / "policy.safetensors"
    assert pretrained_model("DMC-cartpole-swingup-v0", "pretrained") == folder / "policy.safetensors"
    for unknown in ("pretrained:nosuch", "pretrained:../../results/Goalie-v0", "pretrained:drq"):  # drq/ has no agent
        with pytest.raises(VisualEnvError) as caught:
            pretrained_model("DMC-cartpole-swingup-v0", unknown)
        assert str(caught.value) == (
            f"{unknown}: no such shipped agent of DMC-cartpole-swingup-v0; there are pretrained, pretrained:robust, "
            "pretrained:teacher"
        )
    with pytest.raises(VisualEnvError, match="pretrained:robust: no such shipped agent of Goalie-v0; there is only"):
        pretrained_model("Goalie-v0", "pretrained:robust")
    agent = load_agent(REPO / "specs" / "dmc" / "cartpole_swingup.yaml", "pretrained:robust")  # play's and view's way
    assert agent.path == str(folder / "robust" / "policy.safetensors")
    refused = CliRunner().invoke(main, ["eval", "DMC-cartpole-swingup-v0", "--model", "pretrained:nosuch"])
    assert refused.exit_code == 1 and "pretrained:nosuch: no such shipped agent" in refused.output, refused.output


def test_no_pickle_based_file_ships():
    suffixes = {".pt", ".pth", ".pkl", ".pickle", ".zip", ".ckpt"}
    tracked = subprocess.run(["git", "ls-files", "results"], cwd=REPO, capture_output=True, text=True).stdout.split()
    assert tracked and not [name for name in tracked if Path(name).suffix in suffixes]
    assert not (REPO / "visualenv" / "train" / "packed.py").exists()  # the unpickle hook the old files needed is gone
    rllib = read_meta(REPO / "results" / "Goalie-v0-rllib" / "policy.safetensors")
    assert (
        rllib["backend"] == "rllib"
        and rllib["dtype"] == "float16"
        and rllib["arguments"]["catalog_class"].endswith("PPOCatalog")
    )


def _readme_snippet() -> str:
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", readme, re.S)
    (snippet,) = [b for b in blocks if "safetensors" in b]
    return snippet


def test_the_readme_lines_rebuild_a_shipped_policy_with_safetensors_and_sb3_alone():
    """README's recipe, run as written (with an `obs` given), without visualenv: the actions visualenv's loader gives."""
    import io

    obs = np.random.default_rng(0).integers(0, 256, (16, 4, 100, 100), dtype=np.uint8)
    code = (
        "import json, sys\nimport numpy as np\nimport io\nobs = np.load(io.BytesIO(sys.stdin.buffer.read()))\n"
        + _readme_snippet()
        + "\nassert not [m for m in sys.modules if m.split('.')[0] == 'visualenv'], 'visualenv imported'"
        "\nprint(json.dumps(policy.predict(obs, deterministic=True)[0].tolist()))\n"
    )
    buffer = io.BytesIO()
    np.save(buffer, obs)
    result = subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        input=buffer.getvalue(),
        capture_output=True,
        timeout=300,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
    )
    assert result.returncode == 0, result.stderr.decode()[-3000:]
    actions = json.loads(result.stdout.decode().strip().splitlines()[-1])
    ours = load_model(pretrained_model("Goalie-v0")).predict(obs, deterministic=True)[0].tolist()
    assert actions == ours and len(set(ours)) == 2  # both actions among them: the comparison is not of a constant


# -- pickle-based files: refused unless trusted -----------------------------------------------------------------------


def hostile_torch_file(folder: Path, marker: Path) -> Path:
    path = folder / "policy.pt"
    torch.save(
        {
            "state_dict": {},
            "data": Payload(marker),
            "policy_class": "stable_baselines3.common.policies:ActorCriticPolicy",
        },
        path,
    )
    return path


def legit_sb3_zip(folder: Path) -> Path:
    """A real SB3 model (PPO, MLP policy) of VisualCartPole's state vector: nothing renders."""
    from stable_baselines3 import PPO

    import visualenv

    env = visualenv.make("VisualCartPole-v0", render=False)
    model = PPO("MlpPolicy", env, n_steps=32, batch_size=32, seed=0, device="cpu")
    env.close()
    path = folder / "legit.zip"
    model.save(path)
    return path


def hostile_sb3_zip(folder: Path, marker: Path) -> Path:
    """A real SB3 zip whose `data` carries one more entry, cloudpickled as SB3 writes one: SB3's load unpickles it."""
    import cloudpickle

    source, path = legit_sb3_zip(folder), folder / "hostile.zip"
    with zipfile.ZipFile(source) as archive, zipfile.ZipFile(path, "w") as out:
        for entry in archive.infolist():
            content = archive.read(entry)
            if entry.filename == "data":
                data = json.loads(content)
                data["_last_obs"] = {
                    ":type:": "<class 'numpy.ndarray'>",
                    ":serialized:": base64.b64encode(cloudpickle.dumps(Payload(marker))).decode(),
                }
                content = json.dumps(data).encode()
            out.writestr(entry, content)
    return path


def hostile_rllib_checkpoint(folder: Path, marker: Path) -> Path:
    """An RLlib Algorithm checkpoint folder's layout, its RLModule's pickles hostile."""
    module = folder / "checkpoint" / "learner_group" / "learner" / "rl_module" / "default_policy"
    module.mkdir(parents=True)
    for name in ("module_state.pkl", "class_and_ctor_args.pkl"):
        (module / name).write_bytes(pickle.dumps(Payload(marker)))
    (module / "metadata.json").write_text(
        json.dumps(
            {
                "class_and_ctor_args_file": "class_and_ctor_args.pkl",
                "state_file": "module_state",
                "ray_version": "2.60.0",
                "checkpoint_version": "2.1",
            }
        )
    )
    return folder / "checkpoint"


UNSAFE_LOADS = {  # what reads each kind of file when it is trusted: each runs the payload
    "torch": "import torch; torch.load(sys.argv[1], weights_only=False)",
    "sb3": "from stable_baselines3.common.save_util import load_from_zip_file; load_from_zip_file(sys.argv[1])",
    "rllib": "import pickle, pathlib; pickle.loads((pathlib.Path(sys.argv[1]) / 'learner_group/learner/rl_module/default_policy/module_state.pkl').read_bytes())",
}


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    """The three hostile files, each proven to run its code when read the unsafe way (in a child process)."""
    folder = tmp_path_factory.mktemp("hostile")
    files = {
        "torch": hostile_torch_file(folder, folder / "torch.ran"),
        "sb3": hostile_sb3_zip(folder, folder / "sb3.ran"),
        "rllib": hostile_rllib_checkpoint(folder, folder / "rllib.ran"),
    }
    for kind, path in files.items():
        subprocess.run(
            [sys.executable, "-c", "import sys; " + UNSAFE_LOADS[kind], str(path)], capture_output=True, timeout=300
        )
        proof = folder / f"{kind}.ran"
        assert proof.read_text() == "code ran", kind  # a real hostile file: the usual loader runs its code
        proof.unlink()
    return folder, files


@pytest.mark.parametrize("kind", ["torch", "sb3", "rllib"])
@pytest.mark.parametrize(
    "command", [["eval", "VisualCartPole-v0"], ["play", "VisualCartPole-v0"], ["view", "VisualCartPole-v0"]]
)
def test_eval_play_and_view_refuse_a_hostile_file_and_run_nothing(hostile, kind, command):
    folder, files = hostile
    path = files[kind]
    result = CliRunner().invoke(main, [*command, "--model", str(path)])
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.output
    assert not (folder / f"{kind}.ran").exists()  # nothing of the file ran
    assert_refusal(result.output, path)


def assert_refusal(output: str, path: Path) -> None:
    assert (
        output.startswith(f"error: {path} is ")
        and "loading it can run any code it holds" in output
        and "Traceback" not in output
    )
    assert (
        f"`visualenv export-policy --trust-pickle {path} OUT.safetensors`" in output and "pass --trust-pickle" in output
    )


def test_the_command_as_a_user_runs_it_refuses_too(hostile):
    """`visualenv eval` in a process of its own: the exit status and the one error line a user sees."""
    folder, files = hostile
    result = subprocess.run(
        [sys.executable, "-m", "visualenv.cli", "eval", "VisualCartPole-v0", "--model", str(files["sb3"])],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    assert result.returncode == 1 and not (folder / "sb3.ran").exists(), result.stdout + result.stderr
    assert_refusal(result.stderr, files["sb3"])


def test_export_and_the_python_api_refuse_them_too(hostile, tmp_path):
    folder, files = hostile
    for kind, path in files.items():
        result = CliRunner().invoke(main, ["export-policy", str(path), str(tmp_path / "out.safetensors")])
        assert result.exit_code == 1 and "loading it can run any code it holds" in result.output, result.output
        with pytest.raises(PickleRefused, match="trust_pickle=True"):
            load_model(path)
        assert not (folder / f"{kind}.ran").exists() and not list(tmp_path.iterdir())


def test_trust_pickle_means_the_file_runs(hostile):
    """What --trust-pickle does (docs/security.md): the file is unpickled, and its code runs."""
    folder, files = hostile
    result = CliRunner().invoke(main, ["eval", "VisualCartPole-v0", "--model", str(files["torch"]), "--trust-pickle"])
    assert (folder / "torch.ran").read_text() == "code ran"
    assert result.exit_code == 1  # then, not being a policy, it fails to load
    (folder / "torch.ran").unlink()


def test_a_trusted_sb3_zip_evaluates_and_converts_once_to_a_policy_file_that_plays_the_same(tmp_path):
    model = legit_sb3_zip(tmp_path)
    refused = CliRunner().invoke(main, ["eval", "VisualCartPole-v0", "--model", str(model), "--episodes", "2"])
    assert refused.exit_code == 1 and "is an SB3 model: a pickle-based file" in refused.output
    trusted = CliRunner().invoke(
        main,
        [
            "eval",
            "VisualCartPole-v0",
            "--model",
            str(model),
            "--trust-pickle",
            "--episodes",
            "3",
            "--seed",
            "7",
            "-o",
            str(tmp_path / "zip.json"),
        ],
    )
    assert trusted.exit_code == 0, trusted.output
    exported = CliRunner().invoke(
        main, ["export-policy", "--trust-pickle", "--float32", str(model), str(tmp_path / "policy.safetensors")]
    )
    assert exported.exit_code == 0 and "float32 weights" in exported.output and "policy.json" in exported.output, (
        exported.output
    )
    assert read_meta(tmp_path / "policy.json")["algorithm"] == "ppo"
    safe = CliRunner().invoke(
        main,
        [
            "eval",
            "VisualCartPole-v0",
            "--model",
            str(tmp_path / "policy.safetensors"),
            "--episodes",
            "3",
            "--seed",
            "7",
            "-o",
            str(tmp_path / "safe.json"),
        ],
    )
    assert safe.exit_code == 0, safe.output
    played, kept = (json.loads((tmp_path / f"{name}.json").read_text())["per_episode"] for name in ("safe", "zip"))
    assert played == kept
    wrong_name = CliRunner().invoke(main, ["export-policy", "--trust-pickle", str(model), str(tmp_path / "policy.pt")])
    assert wrong_name.exit_code == 2 and "expected a file ending in .safetensors" in wrong_name.output
