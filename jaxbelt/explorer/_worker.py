"""The one background thread of the views' long computations."""

from __future__ import annotations

import threading
from typing import Any


class _Worker:
    """The one background thread of the explorers' long computations (a daemon, started on first use).

    One thread for the process, kept: the first JAX call of a program in a new thread costs a few hundred
    milliseconds more than later ones (measured: 0.6 s against 0.2 s for a 1-mode `design_move`), so a thread per
    computation would pay that at every slider move."""

    def __init__(self):
        self._cond = threading.Condition()
        self._queue: list[Any] = []  # the explorers (`Explorer`) with work pending
        self._thread: threading.Thread | None = None

    def submit(self, explorer: Any) -> None:
        with self._cond:
            if explorer not in self._queue:
                self._queue.append(explorer)
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name="jaxbelt-explore", daemon=True)
                self._thread.start()
            self._cond.notify()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._queue:
                    self._cond.wait()
                explorer = self._queue.pop(0)
            explorer._run_pending()


_WORKERS: list[_Worker] = []
_WORKERS_LOCK = threading.Lock()


def _worker() -> _Worker:
    with _WORKERS_LOCK:
        if not _WORKERS:
            _WORKERS.append(_Worker())
        return _WORKERS[0]
