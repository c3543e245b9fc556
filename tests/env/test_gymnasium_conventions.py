"""A new user's first hour (issue 40): registering your own spec, the messages of common mistakes, Gymnasium's conventions.

Each test feeds the mistake or drives the convention as a user met it; state-only envs, except one build.
"""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from click.testing import CliRunner
from gymnasium.utils.env_checker import check_env

import visualenv
from visualenv.cli import main
from visualenv.env import registration
from visualenv.env.batch import BatchedVectorEnv
from visualenv.errors import SpecError, StepError
from visualenv.spec.loader import load_spec_text

DOCKING = """\
id: {id}
state:
  x: {{init: 0}}
  v: {{init: 0}}
actions:
  continuous:
    thrust: {{low: -1, high: 1}}
    turn: {{low: -1, high: 1}}
dynamics:
  update:
    v: v + thrust * 0.1
    x: x + v
outcomes:
  far: {{when: abs(x) > 1000}}
reward: -abs(x)
max_steps: {max_steps}
"""


def _write(folder: Path, name: str, env_id: str, max_steps: int = 7) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(DOCKING.format(id=env_id, max_steps=max_steps))
    return path


@pytest.fixture
def clean_registry():
    """Ids registered by a test are forgotten after it."""
    before = dict(registration._REGISTERED)
    names = set(gym.registry)
    yield
    registration._REGISTERED.clear()
    registration._REGISTERED.update(before)
    for name in set(gym.registry) - names:
        del gym.registry[name]


def _problems(text: str) -> list[str]:
    try:
        load_spec_text(text, "spec.yaml")
    except SpecError as exc:
        return [str(d) for d in exc.diagnostics]
    return []


# -- 1. your own spec: visualenv.register and $VISUALENV_SPECS_PATH -------------------------------------------


def test_register_a_folder_then_gymnasium_makes_its_ids(tmp_path, clean_registry):
    _write(tmp_path / "mine", "docking.yaml", "FirstHourDocking-v0")
    _write(tmp_path / "mine", "docking_long.yaml", "FirstHourDockingLong-v0", max_steps=9)
    assert visualenv.register(tmp_path / "mine") == [
        "visualenv/FirstHourDocking-v0",
        "visualenv/FirstHourDockingLong-v0",
    ]
    assert gym.spec("visualenv/FirstHourDockingLong-v0").max_episode_steps == 9
    env = gym.make("visualenv/FirstHourDocking-v0")
    env.reset(seed=0)
    assert env.step(np.zeros(2, np.float32))[0].shape == (2,)
    assert (
        visualenv.make("FirstHourDocking-v0").spec.id == "visualenv/FirstHourDocking-v0"
    )  # the id is known to make() too
    assert visualenv.register(tmp_path / "mine" / "docking.yaml") == [
        "visualenv/FirstHourDocking-v0"
    ]  # again: harmless


def test_a_duplicate_id_is_an_error_naming_both_files(tmp_path, clean_registry):
    first = _write(tmp_path / "a", "one.yaml", "FirstHourTwin-v0")
    second = _write(tmp_path / "a", "two.yaml", "FirstHourTwin-v0")
    with pytest.raises(SpecError) as info:
        visualenv.register(tmp_path / "a")
    message = str(info.value)
    assert str(first) in message and str(second) in message and "'FirstHourTwin-v0'" in message
    assert "visualenv/FirstHourTwin-v0" not in gym.registry  # nothing registered
    visualenv.register(first)
    other = _write(tmp_path / "b", "three.yaml", "FirstHourTwin-v0")
    with pytest.raises(SpecError, match=f"{other}:1:1: id: the id 'FirstHourTwin-v0' is also defined by {first}"):
        visualenv.register(other)
    with pytest.raises(SpecError, match="VisualCartPole-v0' is also defined by .*visual_cartpole.yaml"):
        visualenv.register(_write(tmp_path / "c", "copy.yaml", "VisualCartPole-v0"))


def test_register_reports_every_bad_file_located(tmp_path, clean_registry):
    _write(tmp_path, "good.yaml", "FirstHourGood-v0")
    (tmp_path / "bad.yaml").write_text(
        "id: Bad-v0\nstate: {x: {init: 0}}\nactions: {discrete: [{u: 1}]}\nmax_stpes: 3\n"
    )
    with pytest.raises(SpecError, match=r"bad.yaml:4:1: max_stpes: unknown key 'max_stpes' \(did you mean 'max_steps'"):
        visualenv.register(tmp_path)
    (tmp_path / "empty").mkdir()
    with pytest.raises(SpecError, match="empty: no spec files"):
        visualenv.register(tmp_path / "empty")


def test_the_specs_path_variable_registers_and_resolves_and_names_duplicates(tmp_path, monkeypatch, clean_registry):
    first = _write(tmp_path / "p1", "dock.yaml", "FirstHourPath-v0", max_steps=4)
    monkeypatch.setenv("VISUALENV_SPECS_PATH", f"{tmp_path / 'p1'}{__import__('os').pathsep}{tmp_path / 'p2'}")
    assert "visualenv/FirstHourPath-v0" in visualenv.register_bundled()
    assert gym.spec("visualenv/FirstHourPath-v0").max_episode_steps == 4
    assert visualenv.resolve("FirstHourPath-v0") == first
    second = _write(tmp_path / "p2", "dock_copy.yaml", "FirstHourPath-v0")
    visualenv.register_bundled()
    for make in (lambda: visualenv.make("FirstHourPath-v0"), lambda: gym.make("visualenv/FirstHourPath-v0")):
        with pytest.raises(SpecError, match=f"{second}:1:1: id: the id 'FirstHourPath-v0' is also defined by {first}"):
            make()


def test_the_header_reader_finds_the_top_level_id_and_max_steps_in_yaml_and_toml(tmp_path):
    yaml_spec = tmp_path / "a.yaml"
    yaml_spec.write_text('# a comment\nid: "Mine-v3"   # the id\nstate:\n  id: {init: 0}\nmax_steps: 250\n')
    toml_spec = tmp_path / "b.toml"
    toml_spec.write_text('id = "Toml-v0"\nmax_steps = 30\n[state.x]\ninit = 0\n[physics]\nmax_steps = 5\n')
    assert registration.read_header(yaml_spec) == ("Mine-v3", 250)
    assert registration.read_header(toml_spec) == ("Toml-v0", 30)
    (tmp_path / "c.yaml").write_bytes(b"id: Bytes-v0\n\xff\xfe\n")  # not UTF-8: still read, never a crash on import
    assert registration.read_header(tmp_path / "c.yaml") == ("Bytes-v0", None)
    (tmp_path / "d.toml").write_text(
        'id = "Broken-v0"\nmax_steps = 9\n[state.x]\ninit = = 0\n'
    )  # what precedes an error is read
    assert registration.read_header(tmp_path / "d.toml") == ("Broken-v0", 9)
    (tmp_path / "e.yaml").write_text("id: [Listed-v0]\nmax_steps: true\n")  # neither an id nor a step count
    assert registration.read_header(tmp_path / "e.yaml") == (None, None)


def test_an_unknown_id_says_how_to_register_one():
    with pytest.raises(
        SpecError,
        match=r"not a spec file, build folder or known env id .*visualenv.register\(path\).*VISUALENV_SPECS_PATH",
    ):
        visualenv.resolve("Docking2D-v0")


def test_registered_bundled_ids_have_the_specs_max_steps():
    for env_id, path in registration.spec_index().items():
        if path.parent == registration.BUNDLED_DIR:
            assert gym.spec(f"visualenv/{env_id}").max_episode_steps == visualenv.load_spec(path).spec.max_steps


# -- 3. a missing camera, Blender's names for fields -------------------------------------------------------


NO_CAMERA = """\
id: NoCam-v0
scene:
  objects:
    Ball: {primitive: sphere}
    Sun: {light: sun, %s: 3}
state:
  x: {init: 0}
actions:
  discrete: [{u: -1}, {u: 1}]
observation: {camera: ChaserCam, resolution: [16, 16]}
"""


def test_a_scene_without_a_camera_says_so_and_how_to_add_one():
    with pytest.raises(SpecError) as info:
        visualenv.compile_spec(load_spec_text(NO_CAMERA % "strength", "spec.yaml"))
    message = str(info.value)
    assert (
        "spec.yaml:10:23: observation.camera: no camera 'ChaserCam' in the scene: the scene has no camera (objects: Ball, Sun)"
        in message
    )
    assert "add one under scene.objects, e.g. ChaserCam: {camera: perspective" in message
    assert "no names are defined" not in message


@pytest.mark.parametrize("blender_name, ours", [("energy", "strength"), ("colour", "color"), ("position", "location")])
def test_blenders_name_of_a_light_property_suggests_the_specs(blender_name, ours):
    problems = _problems(NO_CAMERA % blender_name)
    assert (
        len(problems) == 1 and f"unknown key '{blender_name}' (did you mean '{ours}'? expected one of:" in problems[0]
    ), problems


# -- 4. Gymnasium's conventions -------------------------------------------------------------------------------


def test_a_batchs_nested_state_info_has_the_masks_sync_vector_envs_make(tmp_path):
    path = _write(tmp_path, "dock.yaml", "FirstHourBatch-v0")
    batch = BatchedVectorEnv(path, 3, render=False)
    sync = gym.vector.SyncVectorEnv([lambda: visualenv.make(path, render=False) for _ in range(3)])
    for vec in (batch, sync):
        _, info = vec.reset(seed=0)
        info = vec.step(np.zeros((3, 2), np.float32))[4]
        assert sorted(info["state"]) == ["_v", "_x", "v", "x"], info["state"]
        assert info["state"]["_x"].dtype == np.bool_ and info["state"]["_x"].all() and info["_state"].all()
    batch.close()
    sync.close()


def test_visualenv_make_sets_the_gymnasium_spec_so_check_env_can_remake_it(tmp_path):
    import warnings

    path = _write(tmp_path, "dock.yaml", "FirstHourSpec-v0")
    env = visualenv.make(path, params=None, render=False)
    assert env.spec is not None and env.spec.id == "visualenv/FirstHourSpec-v0" and env.spec.max_episode_steps == 7
    assert env.spec.kwargs == {"target": str(path.resolve()), "render": False}
    assert env.metadata["render_modes"] == []  # no camera: no render mode to test
    with warnings.catch_warnings():
        warnings.simplefilter(
            "error"
        )  # "Not able to test alternative render modes ... not having a spec" would fail here
        check_env(env)
    again = env.spec.make()
    assert np.array_equal(again.reset(seed=3)[0], env.reset(seed=3)[0])
    with pytest.raises(ValueError, match="needs a camera: the spec has no 'observation'"):
        visualenv.make(path, render_mode="rgb_array")


def test_gymnasiums_time_limit_gives_the_max_steps_outcome(tmp_path, clean_registry):
    """Under the id's own max_episode_steps, a smaller or a larger one, and the batch's: truncated with outcome 'max_steps'."""
    visualenv.register(_write(tmp_path, "dock.yaml", "FirstHourLimit-v0", max_steps=7))
    for limit in (None, 3, 12):
        env = gym.make("visualenv/FirstHourLimit-v0", **({} if limit is None else {"max_episode_steps": limit}))
        env.reset(seed=0)
        steps = 0
        while True:
            steps += 1
            _, _, terminated, truncated, info = env.step(np.zeros(2, np.float32))
            if terminated or truncated:
                break
        assert (steps, truncated, info["outcome"]) == (limit or 7, True, "max_steps")
    vec = gym.make_vec(
        "visualenv/FirstHourLimit-v0", 2, vectorization_mode="vector_entry_point", render=False, max_episode_steps=3
    )
    vec.reset(seed=0)
    for _ in range(3):
        info = vec.step(np.zeros((2, 2), np.float32))[4]
    assert list(info["outcome"]) == ["max_steps", "max_steps"]
    vec.close()
    assert visualenv.make("FirstHourLimit-v0", max_episode_steps=2).unwrapped.max_episode_steps == 2
    with pytest.raises(SpecError, match=r"visualenv.make\(\): max_episode_steps: "):
        visualenv.make("FirstHourLimit-v0", max_episode_steps=0)


# -- 6. a NaN action names the action --------------------------------------------------------------------------


def test_a_nan_action_is_named_as_the_cause_of_the_fault(tmp_path):
    env = visualenv.make(_write(tmp_path, "dock.yaml", "FirstHourNaN-v0"))
    env.reset(seed=0)
    env.step(np.array([0.5, 0.1], np.float32))
    with pytest.raises(StepError) as info:
        env.step(np.array([math.nan, 0.25], np.float32))
    message = str(info.value)
    assert "dock.yaml:11: dynamics.update.v = 'v + thrust * 0.1': state 'v' became nan" in message
    assert "caused by the action, which is not finite: thrust=nan (action=[nan, 0.25])" in message
    batch = BatchedVectorEnv(tmp_path / "dock.yaml", 2, render=False)
    batch.reset(seed=0)
    with pytest.raises(StepError, match=r"caused by the action, which is not finite: thrust=nan"):
        batch.step(np.array([[0.0, 0.0], [math.nan, 0.0]], np.float32))


def test_a_fault_with_a_finite_action_does_not_blame_it(tmp_path):
    text = DOCKING.format(id="FirstHourLog-v0", max_steps=5).replace("x: x + v", "x: log(x + v)")
    path = tmp_path / "log.yaml"
    path.write_text(text)
    env = visualenv.make(path)
    env.reset(seed=0)
    with pytest.raises(StepError) as info:
        env.step(np.array([-0.5, 0.0], np.float32))
    assert "log" in str(info.value) and "caused by the action" not in str(info.value)


# -- 7. smaller points ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "field, value, expected",
    [
        ("scene.objects.Ball.location", "[0, 0]", "expected exactly 3 values, got 2"),
        ("scene.objects.Ball.location", "[0, 0, 0, 1]", "expected exactly 3 values, got 4"),
        ("scene.objects.Ball.material.color", "[1, 0]", "expected 3 or 4 values, got 2"),
        ("observation.resolution", "[32]", "expected exactly 2 values, got 1"),
        ("actors.Ball.location", "[x, 0]", "expected exactly 3 values, got 2"),
    ],
)
def test_a_vector_of_the_wrong_length_gets_one_phrasing(field, value, expected):
    objects = {"Ball": "{primitive: sphere}", "Cam": "{camera: perspective}"}
    actors = ""
    observation = "observation: {camera: Cam, resolution: [16, 16]}\n"
    if field.startswith("scene.objects.Ball.material"):
        objects["Ball"] = "{primitive: sphere, material: {color: %s}}" % value
    elif field.startswith("scene.objects.Ball"):
        objects["Ball"] = "{primitive: sphere, location: %s}" % value
    elif field.startswith("actors"):
        actors = "actors:\n  Ball: {location: %s}\n" % value
    else:
        observation = "observation: {camera: Cam, resolution: %s}\n" % value
    text = (
        "id: V-v0\nscene:\n  objects:\n"
        + "".join(f"    {k}: {v}\n" for k, v in objects.items())
        + "state:\n  x: {init: 0}\nactions:\n  discrete: [{u: 1}]\n"
        + actors
        + observation
    )
    problems = _problems(text)
    assert len(problems) == 1 and f"{field}: {expected}" in problems[0], problems


def test_docs_say_an_outcome_ends_by_terminating_unless_told():
    from visualenv.spec.models import Outcome

    assert Outcome.model_fields["end"].default == "terminate"
    docs = (Path(__file__).resolve().parents[2] / "docs" / "spec.md").read_text()
    assert "`end: terminate \\| truncate \\| none` (default `terminate`)" in docs


@pytest.mark.blender
def test_build_says_an_rgb_observation_is_sketched_in_grayscale(tmp_path):
    spec = tmp_path / "rgb.yaml"
    spec.write_text(
        textwrap.dedent("""\
        id: FirstHourRgb-v0
        scene:
          objects:
            Ball: {primitive: sphere, material: {color: [0.9, 0.1, 0.1]}}
            Sun: {light: sun}
            Cam: {camera: perspective, location: [0, -4, 0], look_at: [0, 0, 0]}
        state:
          x: {init: 0}
        actions:
          discrete: [{u: 1}]
        observation: {camera: Cam, resolution: [16, 12], color: rgb}
        render: {view: {resolution: [32, 24]}}
        """)
    )
    result = CliRunner().invoke(main, ["build", str(spec), "--out", str(tmp_path / "build")])
    assert result.exit_code == 0, result.output
    assert "observation (reset, seed 0; RGB shown as grayscale text; the colours are in preview.png):" in result.output
    result = CliRunner().invoke(main, ["preview", str(spec), "--out", str(tmp_path / "frames"), "--steps", "2"])
    assert result.exit_code == 0, result.output
    assert "preview: 100%" in result.output and "3/3" in result.output  # tqdm's bar on stderr
