"""A clean stop on SIGINT/SIGTERM: the first sets a flag a training loop reads between its iterations (so the run
still saves and evaluates what it has), the second aborts."""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


class StopRequest:
    """Whether a stop was asked for while :meth:`listening`; `after` names what the loop finishes first."""

    def __init__(self, after: str = "this iteration") -> None:
        self.requested = False
        self.after = after

    @contextmanager
    def listening(self) -> Iterator["StopRequest"]:
        """Catch SIGINT and SIGTERM within the block (in the main thread only: no other may set handlers)."""

        def request(signum: int, frame: Any) -> None:
            if self.requested:  # a second Ctrl-C: the user means it
                raise KeyboardInterrupt
            self.requested = True
            print(f"stopping after {self.after}; saving and evaluating (Ctrl-C again to abort)", file=sys.stderr)

        if threading.current_thread() is not threading.main_thread():
            yield self
            return
        previous = {sig: signal.signal(sig, request) for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield self
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
