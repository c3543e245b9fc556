"""The viewer's HTTP server (Werkzeug, in a background thread): the page, its live updates and its inputs.

Routes:

* ``GET /``: the page (:mod:`visualenv.viewer.page`);
* ``GET /events``: the live updates as server-sent events, one JSON snapshot per message (only the pictures that
  changed since the connection's last message, as PNG data URLs);
* ``GET /state``: the latest values as JSON, with the pictures' sizes (for scripts and tests);
* ``GET /picture/<name>``: one picture as a PNG;
* ``POST /input``: a key, pause, step, reset, speed or slider input as JSON (an interactive page only).

Only ``application/json`` inputs are taken: a page of another site cannot send one without the browser asking this
server first (a CORS preflight it does not answer), so it cannot drive the env.
"""

from __future__ import annotations

import base64
import io
import json
import math
import socket
import threading
from typing import Any, Iterator

from PIL import Image
from werkzeug.exceptions import HTTPException, BadRequest, MethodNotAllowed, NotFound, UnsupportedMediaType
from werkzeug.serving import BaseWSGIServer, WSGIRequestHandler, get_sockaddr, make_server, select_address_family
from werkzeug.wrappers import Request, Response

from visualenv.viewer.board import Board, Picture, Snapshot
from visualenv.viewer.page import page_html

#: seconds between keep-alive comments on an idle event stream (a closed page is noticed at the next one)
KEEP_ALIVE_S = 5.0
#: the inputs the page sends, and the fields each takes (name -> checker)
INPUTS = ("key", "pause", "step", "reset", "speed", "slider")
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


class _QuietHandler(WSGIRequestHandler):
    """Werkzeug's handler without a log line per request (the page polls nothing, but streams and posts keys)."""

    def log_request(self, code: int | str = "-", size: int | str = "-") -> None:
        pass


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
            self._server: BaseWSGIServer = make_server(
                host, port, self._wsgi, threaded=True, request_handler=_QuietHandler, fd=listener.fileno()
            )
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
        try:
            message = json.loads(request.get_data(cache=False, as_text=True) or "null")
        except ValueError:
            raise BadRequest("not JSON") from None
        self.board.inputs.put(check_input(message))
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
        if not isinstance(name, str) or not name:
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
        listener.listen(128)
    except BaseException:
        listener.close()
        raise
    return listener


def is_local(host: str) -> bool:
    """Whether `host` serves this machine only."""
    return host in LOCAL_HOSTS


_NO_STORE = {"Cache-Control": "no-store"}


def _json(document: Any) -> Response:
    return Response(json.dumps(document, allow_nan=False), mimetype="application/json", headers=_NO_STORE)
