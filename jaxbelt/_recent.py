"""The last few values computed, by key, shared between threads: the small memos of a warm `design_move`, whose
caller's thread and minimax worker (`jaxbelt.shaping.minimax_solve`) both read and fill them."""

from __future__ import annotations

import collections
import os
import threading
from typing import Any


class Recent:
    """The last `size` `(key, value)` pairs put, looked up by equal keys under one lock. A key of None is never
    kept (`get` gives None, `put` does nothing). A forked child starts empty with a lock of its own: a parent
    thread may hold the lock at the fork, and the child would wait for it forever."""

    def __init__(self, size: int):
        self._items: collections.deque = collections.deque(maxlen=size)
        self._lock = threading.Lock()
        if hasattr(os, "register_at_fork"):
            os.register_at_fork(after_in_child=self._after_fork)

    def _after_fork(self) -> None:
        self._lock = threading.Lock()
        self._items.clear()

    def get(self, key) -> Any:
        """The value put with a key equal to `key` (the earliest kept), or None."""
        if key is None:
            return None
        with self._lock:
            return next((v for k, v in self._items if k == key), None)

    def put(self, key, value) -> None:
        if key is not None:
            with self._lock:
                self._items.append((key, value))

    def clear(self) -> None:
        with self._lock:
            self._items.clear()
