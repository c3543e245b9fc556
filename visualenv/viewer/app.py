"""`visualenv view SPEC_OR_ID`: serve the viewer's page and run its session until Ctrl-C (docs/viewer.md)."""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Callable

from visualenv.env.registration import read_header, resolve
from visualenv.errors import VisualEnvError
from visualenv.train.model_files import PRETRAINED, is_pretrained, load_model, pretrained_model
from visualenv.viewer.board import Board
from visualenv.viewer.server import ViewerServer, allow_open_files, is_local
from visualenv.viewer.session import DEFAULT_VIEW, Agent, Session, ViewOptions

#: `visualenv view`'s port when none is given (any free one where it is taken)
DEFAULT_PORT = 8765


def load_agent(path: Path, model: str, algo: str = "ppo", *, trust_pickle: bool = False) -> Agent:
    """The agent of ``--model``: a policy file, 'pretrained' (the shipped agent of the spec's id), or with `trust_pickle`
    a pickle-based model (an SB3 .zip, a torch .pt, an RLlib checkpoint folder), as `play` loads them."""
    if is_pretrained(model):
        env_id = read_header(path)[0]
        if not env_id:
            raise VisualEnvError(f"{path} has no top-level 'id': --model {PRETRAINED} names the shipped agent of an id")
        file = str(pretrained_model(env_id, model))
    elif not Path(model).exists():
        raise VisualEnvError(f"--model {model}: no such file (or '{PRETRAINED}' for the shipped agent)")
    else:
        file = model
    return Agent(load_model(file, algo, trust_pickle=trust_pickle), file)


def serve(
    target: str,
    *,
    model: str | None = None,
    algo: str = "ppo",
    host: str = "127.0.0.1",
    port: int | None = None,
    seed: int = 0,
    view: ViewOptions = DEFAULT_VIEW,
    echo: Callable[[str], None] = print,
    trust_pickle: bool = False,
    trust_code: bool = False,
) -> None:
    """Serve `target` (a spec file or an id) on ``http://host:port/`` until Ctrl-C, then stop cleanly.

    A spec or model that cannot be found, or a port that cannot be had, raises VisualEnvError before anything is
    served; a spec that does not build is served anyway, with its error on the page, so that saving a fix goes on.
    `trust_code`: the spec's ``dynamics.python`` may be imported (docs/security.md).
    """
    path = resolve(target)
    agent = load_agent(path, model, algo, trust_pickle=trust_pickle) if model else None
    board = Board()
    allow_open_files()
    server = _server(board, host, port, path)
    session = Session(path, board, agent=agent, seed=seed, view=view, trust_code=trust_code)
    server.start()
    try:
        echo(f"visualenv view: {server.url} (Ctrl-C stops)")
        if not is_local(host):
            echo(
                f"warning: --host {host}: anyone who can reach {server.url} can drive the env and read the spec's errors; there is no password"
            )
        session.run()
    except KeyboardInterrupt:
        pass
    finally:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C does not cut the cleanup short
        try:
            server.stop()
            session.close()
        finally:
            signal.signal(signal.SIGINT, previous)
    echo("stopped")


def _server(board: Board, host: str, port: int | None, path: Path) -> ViewerServer:
    try:
        return ViewerServer(board, host=host, port=DEFAULT_PORT if port is None else port, title=path.name)
    except OSError as exc:
        if port is None:  # the default port is taken (another viewer): any free one
            return ViewerServer(board, host=host, port=0, title=path.name)
        raise VisualEnvError(
            f"cannot serve on {host}:{port}: {exc.strerror or exc} (choose another --port; 0 takes any free one)"
        ) from None
