"""The viewer's HTTP server (Werkzeug, in a background thread): the page, its live updates and its inputs.

Routes:

* ``GET /``: the page (:mod:`visualenv.viewer.page`);
* ``GET /events``: the live updates as server-sent events, one JSON snapshot per message (only the pictures that
  changed since the connection's last message, as PNG data URLs);
* ``GET /state``: the latest values as JSON, with the pictures' sizes (for scripts and tests);
* ``GET /picture/<name>``: one picture as a PNG;
* ``POST /input``: a key, pause, step, reset, speed or slider input as JSON (an interactive page only).

Only ``application/json`` inputs are taken: a page of another site cannot send one without the browser asking this
server first (a CORS preflight it does not answer), so it cannot drive the env. A page that rebinds its own name to
this machine is refused by its ``Host`` and ``Origin`` (:mod:`visualenv.viewer.guard`), before any route runs.

What a request can cost is bounded (docs/security.md): a connection that sends nothing for
:data:`CONNECTION_TIMEOUT_S` is closed, a body over :data:`~visualenv.viewer.guard.MAX_BODY_BYTES` is refused unread, at most
:data:`MAX_CONNECTIONS` are served at once, and a malformed request costs one log line, never a traceback.
"""

from __future__ import annotations

import base64
import io
import json
import logging
import math
import queue
import socket
import sys
import threading
from typing import Any, Iterator

from PIL import Image
from werkzeug.exceptions import (
    BadRequest,
    ClientDisconnected,
    HTTPException,
    MethodNotAllowed,
    NotFound,
    ServiceUnavailable,
    UnsupportedMediaType,
)
from werkzeug.serving import ThreadedWSGIServer, WSGIRequestHandler, get_sockaddr, select_address_family
from werkzeug.wrappers import Request, Response

from visualenv.viewer.board import Board, Picture, Snapshot
from visualenv.viewer.guard import LOOPBACK_NAMES, Guard, Refusal
from visualenv.viewer.page import page_html

#: seconds between keep-alive comments on an idle event stream (a closed page is noticed at the next one)
KEEP_ALIVE_S = 5.0
#: the inputs the page sends, and the fields each takes (name -> checker)
INPUTS = ("key", "pause", "step", "reset", "speed", "slider")
#: seconds a connection may take to send its request (or to take a response) before it is closed
CONNECTION_TIMEOUT_S = 5.0
#: seconds an event stream may wait for the page to take its next message (a slow link sends pictures slowly)
STREAM_TIMEOUT_S = 30.0
#: connections served at once, each by a thread until it ends or times out; more are closed unanswered
MAX_CONNECTIONS = 2048
#: connections the listening socket holds before they are accepted
LISTEN_BACKLOG = 1024

#: where the viewer's one-line reports go: refused and malformed requests, errors (stderr where logging is not set up)
log = logging.getLogger("visualenv.viewer")


class _Handler(WSGIRequestHandler):
    """Werkzeug's handler with the viewer's gate: a timeout on the socket, the head checked by the server's
    :class:`Guard` before anything else, one log line per refused or malformed request and no line per request."""

    server: "_Server"

    def setup(self) -> None:
        super().setup()
        self.connection.settimeout(CONNECTION_TIMEOUT_S)

    def parse_request(self) -> bool:
        if not super().parse_request():
            return False  # a malformed head: http.server answered it (400, 431, ...) and logged one line
        refusal = self.server.guard.check(self.path, self.headers)
        if refusal is None:
            return True
        self._refuse(refusal)
        return False

    def handle_expect_100(self) -> bool:
        return True  # Werkzeug sends the 100 Continue itself, once parse_request let the request in

    def _refuse(self, refusal: Refusal) -> None:
        """Answers `refusal` and closes the connection, its body (if any) unread."""
        self.close_connection = True
        self.log_error("refused %s %r: %s", self.command, self.path[:100], refusal.reason)
        body = f"{refusal.reason}\n".encode()
        self.send_response(refusal.status)
        self.send_header("Content-Type", "text/plain; charset=utf-8")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Connection", "close")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def connection_dropped(self, error: BaseException, environ: Any = None) -> None:
        self.close_connection = True  # a stalled or gone client: its socket is not read again

    def log_request(self, code: int | str = "-", size: int | str = "-") -> None:
        pass

    def log_error(self, format: str, *args: Any) -> None:
        if format.startswith("Request timed out"):
            return  # an idle or half-open connection, closed: a browser opens some it never uses
        log.warning("visualenv viewer: %s: " + format, self.client_address[0], *args)


class _Server(ThreadedWSGIServer):
    """Werkzeug's threaded server with a :class:`Guard`, a cap on connections served at once, and one log line where
    Werkzeug or socketserver would print a traceback."""

    block_on_close = False  # stop() does not wait for half-open connections to time out

    def __init__(self, host: str, port: int, app: Any, fd: int) -> None:
        super().__init__(host, port, app, handler=_Handler, fd=fd)
        self.guard = Guard(host, self.port)
        self._slots = threading.BoundedSemaphore(MAX_CONNECTIONS)

    def process_request(self, request: Any, client_address: Any) -> None:
        if not self._slots.acquire(blocking=False):
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._slots.release()
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._slots.release()

    def handle_error(self, request: Any, client_address: Any) -> None:
        error = sys.exc_info()[1]
        log.warning("visualenv viewer: %s: %s: %s", client_address[0], type(error).__name__, error)

    def log(self, type: str, message: str, *args: Any) -> None:
        lines = (message % args if args else message).strip().splitlines() or [""]
        log.warning("visualenv viewer: %s", lines[0] if len(lines) == 1 else f"{lines[0]} {lines[-1]}")


class ViewerServer:
    """Serves a :class:`Board` on ``http://host:port/`` from a daemon thread until :meth:`stop`.

    `interactive` False serves a page that only watches (``render_mode="human"``): it has no controls and refuses inputs.
    Port 0 takes any free port; :attr:`url` says which. A port that cannot be had raises OSError (Werkzeug would exit).
    """

    def __init__(
        self,
        board: Board,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        title: str = "visualenv",
        interactive: bool = True,
    ) -> None:
        self.board = board
        self.title = title
        self.interactive = interactive
        listener = _listen(host, port)
        try:
            self._server = _Server(host, port, self._wsgi, fd=listener.fileno())
        finally:
            listener.close()  # the server holds its own duplicate of the socket
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host = self._server.host
        shown = f"[{host}]" if ":" in host else host
        return f"http://{shown}:{self._server.port}/"

    def start(self) -> "ViewerServer":
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.2}, name="visualenv-viewer", daemon=True
        )
        self._thread.start()
        return self

    def stop(self) -> None:
        """Ends the page connections' streams, stops serving and frees the port."""
        self.board.close()
        if self._thread is not None:
            self._server.shutdown()
            self._thread.join(timeout=5)
        self._server.server_close()

    # -- the WSGI application -------------------------------------------------------------------------

    def _wsgi(self, environ: dict[str, Any], start_response: Any) -> Any:
        request = Request(environ)
        try:
            response = self._route(request)
        except HTTPException as exc:
            response = Response(exc.description or exc.name, status=exc.code, mimetype="text/plain")
        except (ConnectionError, TimeoutError):
            raise  # the client went, or stalled past the timeout: Werkzeug drops the connection without a word
        except Exception as exc:  # noqa: BLE001 - one line on the terminal, not a traceback; the server goes on
            log.warning("visualenv viewer: %s %s: %s: %s", request.method, request.path, type(exc).__name__, exc)
            response = Response(f"{type(exc).__name__}: {exc}", status=500, mimetype="text/plain")
        return response(environ, start_response)

    def _route(self, request: Request) -> Response:
        path = request.path
        if path == "/input":
            if request.method != "POST":
                raise MethodNotAllowed(["POST"])
            return self._input(request)
        if request.method not in ("GET", "HEAD"):
            raise MethodNotAllowed(["GET", "HEAD"])
        if path == "/":
            return Response(page_html(self.title, self.interactive), mimetype="text/html", headers=_NO_STORE)
        if path == "/events":
            connection = request.environ.get("werkzeug.socket")
            if connection is not None:
                connection.settimeout(STREAM_TIMEOUT_S)
            return Response(self._events(), mimetype="text/event-stream", headers=_NO_STORE)
        if path == "/state":
            return _json(state_document(self.board.latest()))
        if path.startswith("/picture/"):
            picture = self.board.latest().pictures.get(path[len("/picture/") :])
            if picture is None:
                raise NotFound(
                    f"no picture {path[len('/picture/') :]!r}: the pictures are {sorted(self.board.latest().pictures)}"
                )
            return Response(png(picture), mimetype="image/png", headers=_NO_STORE)
        raise NotFound(f"no page {path}")

    def _input(self, request: Request) -> Response:
        if not self.interactive:
            raise NotFound("this page only watches (render_mode='human'): it takes no inputs")
        if request.mimetype != "application/json":
            raise UnsupportedMediaType("inputs are JSON (Content-Type: application/json)")
        try:  # the guard let in a body of a few KiB at most, with its Content-Length
            data = request.get_data(cache=False)
        except ClientDisconnected:  # the body stopped short, or stalled past the timeout: dropped without a word
            raise ConnectionAbortedError("the request's body did not come") from None
        try:
            message = json.loads(data or b"null")
        except (ValueError, RecursionError):
            raise BadRequest("not JSON") from None
        try:
            self.board.inputs.put_nowait(check_input(message))
        except queue.Full:
            waiting = self.board.inputs.maxsize
            raise ServiceUnavailable(f"{waiting} inputs wait for the env already: try again") from None
        return Response(status=204)

    def _events(self) -> Iterator[str]:
        """The snapshots as server-sent events, each picture sent again only when it changed."""
        sent: dict[str, int] = {}
        version = -1
        with self.board.watching():
            while not self.board.closed:
                snapshot = self.board.wait(version, KEEP_ALIVE_S)
                if snapshot.version == version:
                    yield ": alive\n\n"
                    continue
                version = snapshot.version
                yield f"data: {json.dumps(event_document(snapshot, sent), allow_nan=False)}\n\n"


def check_input(message: Any) -> dict[str, Any]:
    """A page input as the session takes it, or BadRequest saying what is wrong (never an exception of another kind)."""
    if not isinstance(message, dict) or message.get("type") not in INPUTS:
        raise BadRequest(f"expected an object with 'type' one of {', '.join(INPUTS)}")
    kind = message["type"]
    if kind == "key":
        key, down = message.get("key"), message.get("down")
        if not isinstance(key, str) or not 0 < len(key) <= 20 or not isinstance(down, bool):
            raise BadRequest("a key input is {type: 'key', key: <KeyboardEvent.key>, down: true|false}")
        return {"type": kind, "key": key, "down": down}
    if kind == "reset":
        seed = message.get("seed")
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**32):
            raise BadRequest("a reset's seed is an integer from 0 to 2**32 - 1, or null")
        return {"type": kind, "seed": seed}
    if kind in ("speed", "slider"):
        value = message.get("value")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise BadRequest(f"a {kind} input has a finite number as its 'value'")
        if kind == "speed":
            if not 0 < value <= 1000:
                raise BadRequest("speed is in steps per second, above 0 and at most 1000")
            return {"type": kind, "value": float(value)}
        name = message.get("name")
        if not isinstance(name, str) or not 0 < len(name) <= 100:
            raise BadRequest("a slider input names its input: {type: 'slider', name: ..., value: ...}")
        return {"type": kind, "name": name, "value": float(value)}
    return {"type": kind}


def state_document(snapshot: Snapshot) -> dict[str, Any]:
    """`GET /state`: the values, and each picture's kind and size."""
    pictures = {
        name: {"kind": p.kind, "width": p.pixels.shape[1], "height": p.pixels.shape[0], "version": p.version}
        for name, p in snapshot.pictures.items()
    }
    return {"version": snapshot.version, "values": snapshot.values, "pictures": pictures}


def event_document(snapshot: Snapshot, sent: dict[str, int]) -> dict[str, Any]:
    """One event: the values, every picture's name and kind, and the pictures not yet `sent` in this version (updated)."""
    changed = {}
    for name, picture in snapshot.pictures.items():
        if sent.get(name) != picture.version:
            sent[name] = picture.version
            changed[name] = {
                "src": "data:image/png;base64," + base64.b64encode(png(picture)).decode("ascii"),
                "width": picture.pixels.shape[1],
                "height": picture.pixels.shape[0],
            }
    names = {name: p.kind for name, p in snapshot.pictures.items()}
    for gone in set(sent) - set(names):
        del sent[gone]
    return {"version": snapshot.version, "values": snapshot.values, "names": names, "pictures": changed}


def png(picture: Picture) -> bytes:
    """The picture as PNG bytes (fast compression: the page is on this machine or near it)."""
    pixels = picture.pixels
    image = Image.fromarray(pixels[:, :, 0] if pixels.shape[2] == 1 else pixels)
    out = io.BytesIO()
    image.save(out, format="PNG", compress_level=1)
    return out.getvalue()


def _listen(host: str, port: int) -> socket.socket:
    """A socket listening on host:port, bound here so that a taken port is an OSError (Werkzeug prints and exits)."""
    family = select_address_family(host, port)
    listener = socket.socket(family, socket.SOCK_STREAM)
    try:
        # as http.server does: a port left in TIME_WAIT is free
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(get_sockaddr(host, port, family))
        listener.listen(LISTEN_BACKLOG)
    except BaseException:
        listener.close()
        raise
    return listener


def allow_open_files(wanted: int = 2 * MAX_CONNECTIONS + 256) -> None:
    """Raises this process's soft limit of open files to `wanted`, within its hard limit: at a usual 1,024, a thousand
    held connections would leave the server no descriptor to accept the page's next request with."""
    try:
        import resource
    except ImportError:  # Windows: no such limit to raise
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
    if soft != resource.RLIM_INFINITY and soft < target:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
        except (ValueError, OSError):
            pass


def is_local(host: str) -> bool:
    """Whether `host` serves this machine only."""
    return host in LOOPBACK_NAMES


_NO_STORE = {"Cache-Control": "no-store"}


def _json(document: Any) -> Response:
    return Response(json.dumps(document, allow_nan=False), mimetype="application/json", headers=_NO_STORE)
