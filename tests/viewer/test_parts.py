"""The viewer's parts without Blender: the server's routes and inputs, the board, the keys of a spec's actions, the
files a live edit watches, the session's stepping rules on a state-only spec, the command's refusals, and the cost
of `import visualenv` (no web library).

What the page shows of a rendered env, in a real browser: test_browser.py; `visualenv view` over HTTP and
render_mode="human": test_http.py.
"""

from __future__ import annotations

import base64
import io
import json
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from visualenv.cli import main
from visualenv.compiler.program import compile_spec
from visualenv.env.human import grid
from visualenv.env.registration import resolve
from visualenv.spec.loader import load_spec
from visualenv.viewer import board as board_module
from visualenv.viewer import server as server_module
from visualenv.viewer import session as session_module
from visualenv.viewer.board import VIEW, Board, ViewPacer
from visualenv.viewer.controls import controls_for
from visualenv.viewer.server import ViewerServer
from visualenv.viewer.session import Session, ViewOptions
from visualenv.viewer.watch import FileWatcher, named_files

REPO = Path(__file__).resolve().parents[2]

LINE = """\
id: ViewerLine-v0
state:
  x: {init: 0}
actions:
  discrete:
    - {move: -1}     # 0: left
    - {move: 1}      # 1: right
dynamics:
  update:
    x: x + move
reward: 1.0
outcomes:
  far: {when: abs(x) >= 3, end: terminate}
max_steps: 50
"""


# -- the server ---------------------------------------------------------------------------------------------


@pytest.fixture
def served():
    board = Board()
    server = ViewerServer(board, title="Test<1>").start()
    yield board, server
    server.stop()


def _get(url: str) -> tuple[int, str, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.status, response.headers["Content-Type"], response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.headers["Content-Type"], exc.read()


def _post(url: str, body: bytes, content_type: str = "application/json") -> int:
    request = urllib.request.Request(url, data=body, headers={"Content-Type": content_type})
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status
    except urllib.error.HTTPError as exc:
        return exc.code


def test_the_server_serves_the_page_the_state_and_each_picture(served):
    board, server = served
    gray = np.arange(12 * 10, dtype=np.uint8).reshape(12, 10, 1)
    rgb = np.random.default_rng(0).integers(0, 256, (8, 16, 3), dtype=np.uint8)
    board.publish({"title": "Test", "step": 3, "state": {"x": 1.5}}, {"observation": gray})
    board.publish({"title": "Test", "step": 3, "state": {"x": 1.5}}, {VIEW: rgb}, kind=VIEW)
    status, kind, body = _get(server.url)
    assert status == 200 and kind.startswith("text/html") and b"Test&lt;1&gt;" in body and b"EventSource" in body
    status, kind, body = _get(server.url + "state")
    state = json.loads(body)
    assert state["values"]["step"] == 3 and state["pictures"]["observation"] == {
        "kind": "observation",
        "width": 10,
        "height": 12,
        "version": 1,
    }
    assert state["pictures"][VIEW]["kind"] == VIEW
    status, kind, body = _get(server.url + "picture/observation")
    assert status == 200 and kind == "image/png"
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(body))), gray[:, :, 0])
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(_get(server.url + "picture/view")[2]))), rgb)
    assert _get(server.url + "picture/nothing")[0] == 404
    assert _get(server.url + "nowhere")[0] == 404


def test_the_event_stream_sends_each_snapshot_with_only_the_pictures_that_changed(served, monkeypatch):
    monkeypatch.setattr(server_module, "KEEP_ALIVE_S", 0.2)  # a closed page is noticed at the next keep-alive
    board, server = served
    first = np.full((4, 4, 1), 7, np.uint8)
    board.publish({"step": 0}, {"observation": first})
    events: list[dict] = []

    def listen():
        with urllib.request.urlopen(server.url + "events", timeout=10) as stream:
            for line in stream:
                if line.startswith(b"data: "):
                    events.append(json.loads(line[6:]))
                    if len(events) == 3:
                        return

    listener = threading.Thread(target=listen, daemon=True)
    listener.start()
    _until(lambda: events and board.watched)
    board.update(step=1)  # values only: no picture sent again
    _until(lambda: len(events) >= 2)
    board.publish({"step": 2}, {"observation": first + 1})
    listener.join(timeout=10)
    assert [e["values"]["step"] for e in events] == [0, 1, 2]
    assert (
        list(events[0]["pictures"]) == ["observation"]
        and events[1]["pictures"] == {}
        and list(events[2]["pictures"]) == ["observation"]
    )
    src = events[2]["pictures"]["observation"]["src"]
    assert src.startswith("data:image/png;base64,")
    assert np.asarray(Image.open(io.BytesIO(base64.b64decode(src.split(",", 1)[1])))).max() == 8
    _until(lambda: not board.watched)  # the page went: views are no longer rendered


def test_inputs_are_checked_and_queued_and_a_watching_page_takes_none(served):
    board, server = served
    url = server.url + "input"
    good = [
        {"type": "key", "key": "ArrowLeft", "down": True},
        {"type": "pause"},
        {"type": "step"},
        {"type": "reset", "seed": 4},
        {"type": "reset", "seed": None},
        {"type": "speed", "value": 20},
        {"type": "slider", "name": "main", "value": -0.5},
    ]
    for message in good:
        assert _post(url, json.dumps(message).encode()) == 204, message
    taken = [board.inputs.get_nowait() for _ in good]
    assert taken[0] == good[0] and taken[3]["seed"] == 4 and taken[5] == {"type": "speed", "value": 20.0}
    bad = [
        {"type": "jump"},
        {"type": "key", "key": "a"},
        {"type": "key", "key": "x" * 50, "down": True},
        {"type": "reset", "seed": -1},
        {"type": "reset", "seed": True},
        {"type": "speed", "value": 0},
        {"type": "slider", "name": "main", "value": "1"},
        [1, 2],
    ]
    for message in bad:
        assert _post(url, json.dumps(message).encode()) == 400, message
    assert _post(url, b"{not json") == 400
    assert (
        _post(url, json.dumps(good[1]).encode(), "text/plain") == 415
    )  # what another site's page could send without asking
    assert _get(url)[0] == 405
    assert board.inputs.empty()
    watcher = ViewerServer(Board(), interactive=False).start()
    try:
        assert _post(watcher.url + "input", json.dumps(good[1]).encode()) == 404
        assert b"const INTERACTIVE = false" in _get(watcher.url)[2]
    finally:
        watcher.stop()


def test_a_taken_port_is_an_error_and_stop_frees_the_port():
    board = Board()
    server = ViewerServer(board).start()
    port = int(server.url.rsplit(":", 1)[1].strip("/"))
    with pytest.raises(OSError):
        ViewerServer(Board(), port=port)
    server.stop()
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", port))


# -- the board ----------------------------------------------------------------------------------------------


def test_the_board_replaces_pictures_by_kind_and_removes_those_given_as_none():
    board = Board()
    one = np.zeros((2, 2), np.uint8)
    board.publish({"a": 1}, {"left": one, "right": one})
    board.publish({"a": 2}, {VIEW: one}, kind=VIEW)
    board.publish({"a": 3}, {"front": one}, only=True)  # a rebuilt env with another camera: its observations only
    assert sorted(board.latest().pictures) == ["front", VIEW]
    assert board.latest().pictures["front"].pixels.shape == (2, 2, 1)
    board.publish({"a": 4}, {VIEW: None})
    assert sorted(board.latest().pictures) == ["front"] and board.latest().values == {"a": 4}
    assert board.wait(after=4, timeout=0.01).version == 4  # nothing newer: the latest, after the timeout
    with pytest.raises(ValueError, match="shape"):
        board.publish({}, {"bad": np.zeros((2, 2, 2), np.uint8)})


def test_views_are_paced_to_a_quarter_of_the_time(monkeypatch):
    clock = [100.0]
    monkeypatch.setattr(board_module.time, "monotonic", lambda: clock[0])
    pacer = ViewPacer()
    assert pacer.due()
    pacer.took(started=99.0)  # a view of 1 s: the next one 3 s after it ended
    clock[0] = 102.9
    assert not pacer.due()
    clock[0] = 103.0
    assert pacer.due()


def test_a_grid_tiles_a_batch_row_by_row_one_pixel_apart():
    batch = np.stack([np.full((3, 4, 1), i + 1, np.uint8) for i in range(5)])
    tiled = grid(batch)
    assert tiled.shape == (2 * 4 - 1, 3 * 5 - 1, 1)  # 5 envs: 3 columns, 2 rows
    for i in range(5):
        r, c = divmod(i, 3)
        assert (tiled[r * 4 : r * 4 + 3, c * 5 : c * 5 + 4] == i + 1).all()
    assert tiled[3].max() == 0 and tiled[:, 4].max() == 0  # the gaps
    assert grid(np.zeros((100, 2, 2, 1), np.uint8)).shape == (8 * 3 - 1, 8 * 3 - 1, 1)  # 64 envs at most


# -- keys ---------------------------------------------------------------------------------------------------


def _controls(env_id: str):
    return controls_for(compile_spec(load_spec(resolve(env_id))))


def test_arrow_keys_follow_the_direction_each_action_moves_its_input():
    cartpole = _controls("VisualCartPole-v0")
    assert cartpole.keys == {"ArrowLeft": 0, "0": 0, "ArrowRight": 1, "1": 1}
    assert cartpole.labels[1] == "1: force = force_mag"
    hover = _controls("Hover2D-v0")  # up, down, left, right pulses (ax first: the arrows left/right)
    assert {k: v for k, v in hover.keys.items() if k.startswith("Arrow")} == {
        "ArrowUp": 0,
        "ArrowDown": 1,
        "ArrowLeft": 2,
        "ArrowRight": 3,
    }
    assert _controls("Goalie-v0").keys["ArrowRight"] == 1


def test_continuous_inputs_get_sliders_and_held_arrows():
    lunar = _controls("LunarLanding-v0")
    assert lunar.inputs == [("main", -1.0, 1.0), ("side", -1.0, 1.0)] and lunar.slider_start() == [0.0, 0.0]
    assert lunar.holds == {"ArrowLeft": (0, -1.0), "ArrowRight": (0, 1.0), "ArrowDown": (1, -1.0), "ArrowUp": (1, 1.0)}
    assert [s["name"] for s in lunar.page([0.5, 0.0])["sliders"]] == ["main", "side"]


def test_an_action_whose_sign_cannot_be_read_gets_a_digit_only(tmp_path):
    spec = tmp_path / "odd.yaml"
    spec.write_text(LINE.replace("{move: -1}", "{move: -1 * 2}").replace("{move: 1}", "{move: 1}\n    - {move: 2}"))
    controls = controls_for(compile_spec(load_spec(spec)))
    assert controls.keys == {"0": 0, "1": 1, "2": 2}  # right is not one action's: no arrows at all for 'move'


# -- the files of a live edit -------------------------------------------------------------------------------


def test_a_spec_watches_itself_and_the_files_it_names(tmp_path):
    texture = tmp_path / "floor.png"
    Image.new("RGB", (4, 4)).save(texture)
    spec = tmp_path / "room.yaml"
    spec.write_text(
        LINE
        + "scene:\n  objects:\n    Floor: {primitive: plane, material: {texture: {type: image, image: floor.png}}}\n"
    )
    assert set(named_files(load_spec(spec))) == {spec.resolve(), texture.resolve()}


def test_the_watcher_sees_a_write_a_replacement_and_a_removal(tmp_path):
    spec = tmp_path / "a.yaml"
    spec.write_text("one")
    watcher = FileWatcher([spec])
    assert not watcher.changed()
    spec.write_text("one, longer")
    assert watcher.changed() and not watcher.changed()
    replacement = tmp_path / "b.yaml"
    replacement.write_text("two")
    replacement.replace(spec)  # an editor's save by rename
    assert watcher.changed()
    spec.unlink()
    assert watcher.changed()
    texture = tmp_path / "c.png"
    texture.write_text("x")
    watcher.watch([spec, texture])  # spec keeps its last state (removed), texture is measured from now
    assert not watcher.changed()
    spec.write_text("back")  # saved while a rebuild ran: still a change
    assert watcher.changed()


# -- the session's stepping rules (a state-only spec: no Blender) -----------------------------------------


@pytest.fixture
def line(tmp_path, monkeypatch):
    monkeypatch.setattr(session_module, "END_HOLD_S", 0.0)
    spec = tmp_path / "line.yaml"
    spec.write_text(LINE)
    session = Session(spec, Board(), seed=5, view=ViewOptions(None))
    session.rebuild()
    yield session
    session.close()


def _press(session: Session, key: str, down: bool = True) -> None:
    session.take({"type": "key", "key": key, "down": down})


def test_a_tap_steps_once_a_held_key_repeats_and_no_key_waits(line):
    assert line.values()["status"] == "waiting for a key" and line.values()["step"] == 0
    _press(line, "ArrowRight")
    _press(line, "ArrowRight", down=False)  # a tap shorter than a step
    line.advance()
    line.advance()
    assert line.info["state"]["x"] == 1.0
    _press(line, "ArrowLeft")
    for _ in range(2):
        line.next_step_at = 0.0  # the speed's wait, passed
        line.advance()
    assert line.info["state"]["x"] == -1.0 and line.values()["action"] == "0: move = -1"
    _press(line, "ArrowLeft", down=False)
    line.next_step_at = 0.0
    line.advance()
    assert line.info["steps"] == 3 and line.values()["status"] == "waiting for a key"


def test_pause_single_steps_reset_and_the_next_episode(line):
    line.take({"type": "step"})  # pauses, then one step with the last action (0)
    line.advance()
    assert line.paused and line.info["state"]["x"] == -1.0
    line.take({"type": "reset", "seed": 9})
    assert line.seed == 9 and line.info["steps"] == 0
    line.take({"type": "pause"})
    _press(line, "0")
    for _ in range(3):
        line.next_step_at = 0.0
        line.advance()
    assert line.info["outcome"] == "far" and line.values()["return"] == 3.0
    line.advance()  # the ended episode's hold (0 s here), then the next seed
    assert line.seed == 10 and line.info["steps"] == 0 and line.episode == 3


def test_a_broken_edit_shows_its_located_error_and_the_last_good_env_goes_on(line):
    path = line.path
    path.write_text(LINE.replace("reward: 1.0", "reward: 1.0 + speedd"))
    line.rebuild()
    line_no = LINE.splitlines().index("reward: 1.0") + 1
    error = line.values()["error"]
    assert error.startswith(f"{path}:{line_no}:15: reward: unknown name 'speedd'"), error
    _press(line, "1")
    line.advance()
    assert line.info["state"]["x"] == 1.0 and line.builds == 1  # the last good env stepped
    path.write_text(LINE.replace("x: x + move", "x: x + 2 * move"))
    line.rebuild()
    assert line.values()["error"] is None and line.builds == 2 and line.info["steps"] == 0
    _press(line, "1", down=False)
    _press(line, "1")
    line.advance()
    assert line.info["state"]["x"] == 2.0  # the edited dynamics


def test_an_error_while_stepping_pauses_and_a_reset_goes_on(line, tmp_path):
    line.path.write_text(LINE.replace("x: x + move", "x: x + move / (x - 1)"))
    line.rebuild()
    _press(line, "1")
    line.advance()  # x: 0 -> -1
    _press(line, "1", down=False)
    line.path.write_text(LINE.replace("x: x + move", "x: x + move / (x + 1)"))
    line.rebuild()
    _press(line, "0")
    line.advance()  # x: 0 + -1 / 1 = -1
    line.next_step_at = 0.0
    line.advance()  # -1 / 0
    assert "division by zero" in line.values()["error"] and line.paused
    line.take({"type": "reset", "seed": None})
    assert line.values()["error"] is None and line.info["steps"] == 0


def test_an_agent_steps_without_keys(tmp_path, monkeypatch):
    import gymnasium as gym

    class Rightwards:
        """An agent of the spec's spaces that always moves right."""

        observation_space = gym.spaces.Box(-np.finfo(np.float32).max, np.finfo(np.float32).max, (1,), np.float32)
        action_space = gym.spaces.Discrete(2)

        def predict(self, obs, deterministic=True):
            return np.array(1), None

    spec = tmp_path / "line.yaml"
    spec.write_text(LINE)
    session = Session(spec, Board(), agent=session_module.Agent(Rightwards(), "rightwards"), view=ViewOptions(None))
    session.rebuild()
    session.advance()
    assert (
        session.info["state"]["x"] == 1.0
        and session.values()["mode"] == "agent: rightwards"
        and session.values()["status"] == "running"
    )
    session.close()


# -- the command --------------------------------------------------------------------------------------------


def test_view_refuses_an_unknown_spec_a_missing_model_and_a_taken_port():
    result = CliRunner().invoke(main, ["view", "NoSuchEnv-v0"])
    assert result.exit_code == 2 and "NoSuchEnv-v0" in result.output and "Traceback" not in result.output
    result = CliRunner().invoke(main, ["view", "VisualCartPole-v0", "--model", "nowhere.zip"])
    assert result.exit_code == 1 and "--model nowhere.zip: no such file" in result.output
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = CliRunner().invoke(main, ["view", "VisualCartPole-v0", "--port", str(port)])
    assert result.exit_code == 1 and f"cannot serve on 127.0.0.1:{port}" in result.output


def test_a_batch_split_among_workers_refuses_human_mode():
    from visualenv.env.batch_workers import MultiBatchVectorEnv

    with pytest.raises(ValueError, match="render_mode='human' shows one batch: leave workers out"):
        MultiBatchVectorEnv("VisualCartPole-v0", 4, 2, render_mode="human")


def test_import_visualenv_loads_no_web_library():
    code = (
        "import sys, visualenv, visualenv.cli; "
        "assert not {'werkzeug', 'visualenv.viewer.server', 'visualenv.viewer.human'} & set(sys.modules)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert result.returncode == 0, result.stderr


def _until(condition, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)
