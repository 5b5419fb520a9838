"""Hand payloads from the link's thread to the executor's thread.

The link calls `on_payload` from its own thread; rclpy entities must only be touched from
the executor. `Inbox.put` is safe from any thread: it appends to a bounded queue and
wakes the executor (through an rclpy guard condition in the bridge), whose callback
drains the queue. If the executor falls so far behind that the queue is full, the new
payload is dropped and counted rather than letting memory grow.
"""
from __future__ import annotations

import threading
from collections import deque
from typing import Callable


class Inbox:
    def __init__(self, wake: Callable[[], None], capacity: int = 1024):
        self._wake = wake
        self._capacity = capacity
        self._items: deque[bytes] = deque()
        self._lock = threading.Lock()
        self.overflow = 0
        self.closed = False

    def put(self, payload: bytes) -> bool:
        with self._lock:
            if self.closed:
                return False
            if len(self._items) >= self._capacity:
                self.overflow += 1
                return False
            self._items.append(payload)
        try:
            self._wake()
        except Exception:  # the executor is going away; the payload is simply not handled
            pass
        return True

    def drain(self, limit: int | None = None) -> list[bytes]:
        with self._lock:
            n = len(self._items) if limit is None else min(limit, len(self._items))
            return [self._items.popleft() for _ in range(n)]

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)

    def close(self) -> None:
        with self._lock:
            self.closed = True
            self._items.clear()
