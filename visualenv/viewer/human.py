"""``render_mode="human"``: an env's steps shown live on the viewer's page, as Gymnasium's human mode shows a window.

Every human-mode env of a process shows on one page, served from a background thread started by the first one
(it prints the URL once, to stderr); the last env that stepped is the one shown. Nothing waits for a browser:
without one, a step costs a copy of its observation. While a page watches, the env's high-resolution view is
rendered too, paced to a quarter of the time (:class:`~visualenv.viewer.board.ViewPacer`).

The port is ``$VISUALENV_VIEWER_PORT`` (default 8765), or any free one where that is taken.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from typing import Any, Callable, Mapping

import numpy as np

from visualenv.viewer.board import VIEW, Board, ViewPacer, observation_pictures, plain

PORT_VARIABLE = "VISUALENV_VIEWER_PORT"
DEFAULT_PORT = 8765

_lock = threading.Lock()
_shared: Any = None  # the process's ViewerServer, started by the first human-mode env


def shared_board() -> tuple[Board, str]:
    """The board every human-mode env of this process shows on, and its URL; the server starts on the first call."""
    global _shared
    with _lock:
        if _shared is None:
            from visualenv.viewer.server import ViewerServer

            board = Board()
            try:
                server = ViewerServer(board, port=_port(), title="render_mode='human'", interactive=False)
            except OSError:  # the port is taken (another process's viewer): any free one
                server = ViewerServer(board, port=0, title="render_mode='human'", interactive=False)
            _shared = server.start()
            print(f"visualenv: render_mode='human' shows the env at {server.url}", file=sys.stderr, flush=True)
        return _shared.board, _shared.url


class PageDisplay:
    """One env's frames on the shared page: its observation, its values and, while the page is open, its view.

    It meets :class:`visualenv.env.human.HumanDisplay`; :func:`visualenv.viewer.open_display` makes one per env.
    """

    def __init__(self) -> None:
        self.board, self.url = shared_board()
        self._pacer = ViewPacer()
        self._return = 0.0

    def show(
        self, title: str, observation: Any, values: Mapping[str, Any], view: Callable[[], np.ndarray] | None = None
    ) -> None:
        """A step (or reset, when ``values["reward"]`` is None) of the env titled `title`.

        `observation` is the env's image observation (an array, or a dict by camera; None for a state vector);
        `view` renders the high-resolution view, called only while a page watches and the pacer allows. A batch
        passes its grid of observations and no reward (``values`` then hold no return).
        """
        renamed = {"steps": "step", "is_success": "success"}  # the env's info keys, as the page names them
        shown = plain(
            {
                "title": title,
                "env": title,
                **{renamed.get(k, k): v for k, v in values.items()},
                "status": "render_mode='human'",
            }
        )
        if "reward" in values:  # one env's step (None: its reset): the episode's return so far
            self._return = 0.0 if values["reward"] is None else self._return + float(values["reward"])
            shown["return"] = self._return
        pictures: dict[str, Any] = observation_pictures(observation)
        if view is None:
            pictures["view"] = None  # another env's view, shown before this one, goes
        self.board.publish(shown, pictures, only=True)
        if view is not None and self.board.watched and self._pacer.due():
            started = time.monotonic()
            frame = view()
            self._pacer.took(started)
            self.board.publish(shown, {"view": frame}, kind=VIEW)

    def close(self) -> None:
        """The env closed: the page says so (the server stays for the process's next human-mode env)."""
        self.board.update(status="closed")


def _port() -> int:
    text = os.environ.get(PORT_VARIABLE, "")
    try:
        port = int(text) if text else DEFAULT_PORT
    except ValueError:
        port = DEFAULT_PORT
    return port if 0 <= port < 65536 else DEFAULT_PORT
