"""Hostile requests to the viewer's server, sent over real sockets: another site's names (DNS rebinding) and origins,
bodies too large or malformed, connections left half-open, and a flood of inputs before a pause. No Blender: the
server serves a board, and the flood drives a session of a state-only spec.
"""

from __future__ import annotations

import json
import socket
import threading
import time

import pytest

from visualenv.viewer import server as server_module
from visualenv.viewer.board import MAX_QUEUED_INPUTS, Board
from visualenv.viewer.guard import MAX_BODY_BYTES, Guard, split_authority
from visualenv.viewer.server import ViewerServer
from visualenv.viewer.session import MAX_PENDING_STEPS, Session, ViewOptions, shown_path

LINE = """\
id: ViewerLine-v0
state:
  x: {init: 0}
actions:
  discrete:
    - {move: -1}
    - {move: 1}
dynamics:
  update:
    x: x + move
reward: 1.0
max_steps: 100000
"""
PAUSE = json.dumps({"type": "pause"}).encode()


@pytest.fixture
def served():
    board = Board()
    server = ViewerServer(board).start()
    yield board, server
    server.stop()


def port_of(server: ViewerServer) -> int:
    return int(server.url.rsplit(":", 1)[1].strip("/"))


def exchange(port: int, data: bytes, timeout: float = 10.0) -> tuple[int, bytes]:
    """Sends `data` as it is on a new connection; the response's status (0: none) and body."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as connection:
        connection.sendall(data)
        received = b""
        try:
            while chunk := connection.recv(65536):
                received += chunk
        except ConnectionResetError:
            pass
    head, _, body = received.partition(b"\r\n\r\n")
    return (int(head.split()[1]) if head.startswith(b"HTTP/") else 0), body


def status_of(port: int, data: bytes) -> int:
    """Sends `data` on a new connection; the response's status, read without waiting for the connection's end."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as connection:
        connection.sendall(data)
        return int(connection.recv(12)[9:12])


def request(
    port: int, method: str, path: str, *, host: str | None = None, headers: dict | None = None, body: bytes = b""
) -> bytes:
    """An HTTP/1.1 request's bytes, Host 127.0.0.1:port unless `host` says otherwise ('' leaves it out)."""
    host = f"127.0.0.1:{port}" if host is None else host
    lines = [f"{method} {path} HTTP/1.1"] + ([f"Host: {host}"] if host else [])
    fields = {"Content-Type": "application/json", "Content-Length": str(len(body))} if body else {}
    lines += [f"{k}: {v}" for k, v in {**fields, **(headers or {})}.items()]
    return ("\r\n".join(lines) + "\r\n\r\n").encode() + body


def viewer_lines(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "visualenv.viewer"]


def test_a_page_of_another_name_can_neither_drive_the_env_nor_read_the_state(served, caplog):
    board, server = served
    board.publish({"title": "secret", "spec": "line.yaml"})
    port = port_of(server)
    rebound = f"attacker.example:{port}"  # the attacker's name, pointed at 127.0.0.1: the port is the viewer's
    origin = {"Origin": f"http://{rebound}"}
    for host in (rebound, f"127.0.0.1.attacker.example:{port}", f"localhost:{port + 1}", "localhost", ""):
        assert exchange(port, request(port, "POST", "/input", host=host, headers=origin, body=PAUSE))[0] == 421, host
        status, body = exchange(port, request(port, "GET", "/state", host=host))
        assert status == 421 and b"secret" not in body, host
    assert exchange(port, b"GET http://attacker.example/state HTTP/1.1\r\nHost: 127.0.0.1:%d\r\n\r\n" % port)[0] == 400
    assert board.inputs.empty()
    assert len(viewer_lines(caplog)) == 11 and "attacker.example" in viewer_lines(caplog)[0]
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"LOCALHOST:{port}", f"[::1]:{port}"):
        status, body = exchange(port, request(port, "GET", "/state", host=host))
        assert status == 200 and json.loads(body)["values"]["title"] == "secret", host


def test_an_origin_must_be_the_viewers_own_page(served):
    board, server = served
    port = port_of(server)
    for origin in (
        f"http://attacker.example:{port}",
        "null",
        f"https://127.0.0.1:{port}",
        f"http://localhost:{port + 1}",
    ):
        status, _ = exchange(port, request(port, "POST", "/input", headers={"Origin": origin}, body=PAUSE))
        assert status == 403, origin
    assert board.inputs.empty()
    for origin in (f"http://127.0.0.1:{port}", f"http://localhost:{port}"):
        assert exchange(port, request(port, "POST", "/input", headers={"Origin": origin}, body=PAUSE))[0] == 204
    assert board.inputs.qsize() == 2


def test_the_names_a_viewer_answers_to():
    local = Guard("127.0.0.1", 8765)
    assert local.allows("localhost:8765") and local.allows("[::1]:8765") and not local.allows("localhost:8766")
    assert not local.allows("192.168.1.5:8765") and not local.allows("localhost:8765@evil") and not local.allows("")
    everywhere = Guard("0.0.0.0", 8765)  # an IP address cannot be rebound: any of them, and the machine's name
    assert everywhere.allows("192.168.1.5:8765") and everywhere.allows("[fe80::1]:8765")
    assert not everywhere.allows("attacker.example:8765")
    named = Guard("viewer.lan", 80)
    assert named.allows("viewer.lan") and named.allows("viewer.lan:80") and not named.allows("viewer.lan:8080")
    assert split_authority("[::1]:99") == ("::1", 99) and split_authority("a:b") is None


def test_a_large_body_is_refused_unread_and_a_malformed_one_costs_one_line(served, caplog, capfd):
    board, server = served
    port = port_of(server)
    huge = request(port, "POST", "/input", headers={"Content-Type": "application/json", "Content-Length": "1000000000"})
    started = time.monotonic()
    status, body = exchange(port, huge)  # the head alone: an answer now means the body was never waited for
    assert status == 413 and f"at most {MAX_BODY_BYTES}".encode() in body and time.monotonic() - started < 5
    with socket.create_connection(("127.0.0.1", port), timeout=10) as connection:  # the body coming: still refused
        connection.sendall(huge + b"x" * 65536)
        assert connection.recv(100).startswith(b"HTTP/1.1 413")
    chunked = request(
        port, "POST", "/input", headers={"Content-Type": "application/json", "Transfer-Encoding": "chunked"}
    )
    assert exchange(port, chunked + b"zz\r\n{}\r\n0\r\n\r\n")[0] == 411  # a bad chunk size
    assert exchange(port, request(port, "POST", "/input", headers={"Content-Length": "-1"}))[0] == 400
    lines = viewer_lines(caplog)
    assert len(lines) == 4 and "1000000000 bytes" in lines[0] and "Transfer-Encoding" in lines[2], lines
    caplog.clear()
    too_many = b"GET /state HTTP/1.1\r\n" + b"X-A: b\r\n" * 101 + b"\r\n"
    assert exchange(port, too_many)[0] == 431  # a head http.server refuses
    assert exchange(port, request(port, "POST", "/input", body=b"[" * 4000))[0] == 400  # JSON too deep: not JSON
    assert exchange(port, request(port, "POST", "/input", body=b"\xff\xfe"))[0] == 400
    assert len(viewer_lines(caplog)) == 1
    assert board.inputs.empty() and "Traceback" not in capfd.readouterr().err


def test_half_open_connections_time_out_and_the_state_still_answers(served, monkeypatch):
    monkeypatch.setattr(server_module, "CONNECTION_TIMEOUT_S", 1.0)
    board, server = served
    board.publish({"step": 7})
    port = port_of(server)
    promised = request(port, "POST", "/input", headers={"Content-Type": "application/json", "Content-Length": "100"})
    stalled = []
    try:
        for i in range(200):  # a head begun and never ended, a body promised and never sent, or nothing at all
            connection = socket.create_connection(("127.0.0.1", port), timeout=10)
            connection.sendall([b"GET /state HTTP/1.1\r\nHost: 127.0.0.1", promised + b"{", b""][i % 3])
            stalled.append(connection)
        started = time.monotonic()
        status, body = exchange(port, request(port, "GET", "/state"))
        assert status == 200 and json.loads(body)["values"]["step"] == 7 and time.monotonic() - started < 5
        for connection in stalled:  # each closed by the server after its timeout, unanswered
            assert connection.recv(4096) == b""
        assert board.inputs.empty()
    finally:
        for connection in stalled:
            connection.close()


def test_inputs_wait_in_a_bounded_queue(served):
    board, server = served
    port = port_of(server)
    codes = [status_of(port, request(port, "POST", "/input", body=PAUSE)) for _ in range(MAX_QUEUED_INPUTS + 5)]
    assert codes.count(204) == MAX_QUEUED_INPUTS and codes[-5:] == [503] * 5
    assert board.inputs.qsize() == MAX_QUEUED_INPUTS


def test_a_flood_of_inputs_does_not_delay_the_pause_after_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path.parent)
    spec = tmp_path / "line.yaml"
    spec.write_text(LINE)
    board = Board()
    session = Session(spec, board, view=ViewOptions(None))
    session.rebuild()
    reset = session.env.reset

    def slow_reset(**kwargs):  # a rendered env's reset takes a few milliseconds: 3,000 of them, seconds
        time.sleep(0.005)
        return reset(**kwargs)

    session.env.reset = slow_reset
    server = ViewerServer(board).start()
    port = port_of(server)
    stop = threading.Event()

    def loop():  # Session.run without the file watcher
        while not stop.is_set():
            session.take_inputs(0.02)
            session.advance()

    stepping = threading.Thread(target=loop, daemon=True)
    stepping.start()
    flood = request(port, "POST", "/input", body=json.dumps({"type": "reset", "seed": 3}).encode())
    codes: list[int] = []

    def send(count: int) -> None:
        codes.extend(status_of(port, flood) for _ in range(count))

    try:
        senders = [threading.Thread(target=send, args=(375,)) for _ in range(8)]
        for sender in senders:
            sender.start()
        for sender in senders:
            sender.join()
        assert len(codes) == 3000 and set(codes) <= {204, 503} and codes.count(204) > 0
        assert exchange(port, request(port, "POST", "/input", body=PAUSE))[0] == 204
        paused_at = time.monotonic()
        while not json.loads(exchange(port, request(port, "GET", "/state"))[1])["values"]["paused"]:
            assert time.monotonic() - paused_at < 2, "the pause waited behind the flood"
            time.sleep(0.01)
        assert session.episode < codes.count(204)  # resets that came together ran once
    finally:
        stop.set()
        stepping.join(timeout=10)
        server.stop()
        session.close()
    assert shown_path(spec) == f"{tmp_path.name}/line.yaml" and shown_path("/elsewhere/secret/x.yaml") == "x.yaml"


def test_taps_and_single_steps_wait_in_a_bounded_backlog(tmp_path):
    spec = tmp_path / "line.yaml"
    spec.write_text(LINE)
    session = Session(spec, Board(), view=ViewOptions(None))
    session.rebuild()
    try:
        for _ in range(100):
            session.take({"type": "key", "key": "1", "down": True})
            session.take({"type": "key", "key": "1", "down": False})
        assert len(session.taps) == MAX_PENDING_STEPS
        session.take({"type": "pause"})
        for _ in range(100):
            session.take({"type": "step"})
        assert session.paused and session.step_requests == MAX_PENDING_STEPS
        session.take({"type": "pause"})  # running again: the single steps asked for are dropped
        assert not session.paused and session.step_requests == 0 and not session.taps
    finally:
        session.close()


def test_a_refused_request_is_answered_before_its_body_is_asked_for(served, caplog):
    board, server = served
    port = port_of(server)
    head = request(port, "POST", "/input", headers={"Expect": "100-continue", "Content-Type": "application/json"})
    head = head.replace(b"\r\n\r\n", b"\r\nContent-Length: 1000000000\r\n\r\n")
    with socket.create_connection(("127.0.0.1", port), timeout=10) as connection:
        connection.sendall(head)
        assert connection.recv(100).startswith(b"HTTP/1.1 413")  # no 100 Continue before it
    assert board.inputs.empty() and len(viewer_lines(caplog)) == 1
