"""A tiny stand-in for one DESERT node's socket, for connection tests (127.0.0.1 only).

Serves one client at a time, records what it reads (with arrival times), can send to the client,
kick it, and be stopped and restarted on the same port like a restarted DESERT.
"""
from __future__ import annotations

import socket
import threading
import time

from emulator.helpers import wait_for


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(cond, timeout: float = 5.0) -> bool:
    """emulator.helpers.wait_for with the 5 s patience these thread-and-socket tests were written for."""
    return wait_for(cond, timeout)


class TinyServer:
    def __init__(self, port: int = 0, echo: bool = False):
        self.port = port
        self.echo = echo                               # send everything read back to the client
        self.received = bytearray()
        self.reads: list[tuple[float, int]] = []      # (monotonic time, bytes) per recv
        self.clients = 0
        self._lock = threading.Lock()
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._running = False

    def start(self) -> TinyServer:
        ls = socket.socket()
        ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        ls.bind(("127.0.0.1", self.port))
        ls.listen(1)
        ls.settimeout(0.05)
        self.port = ls.getsockname()[1]
        self._listener = ls
        self._running = True
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()
        return self

    def _serve(self) -> None:
        while self._running:
            try:
                c, _ = self._listener.accept()
            except (TimeoutError, OSError):
                continue
            c.settimeout(0.05)
            with self._lock:
                self._client = c
                self.clients += 1
            while self._running:
                try:
                    data = c.recv(65536)
                except TimeoutError:
                    continue
                except OSError:
                    break
                if not data:
                    break
                with self._lock:
                    self.received += data
                    self.reads.append((time.monotonic(), len(data)))
                if self.echo:
                    try:
                        c.sendall(data)
                    except OSError:
                        break
            with self._lock:
                self._client = None
            try:
                c.close()
            except OSError:
                pass

    @property
    def has_client(self) -> bool:
        return self._client is not None

    def send(self, data: bytes) -> None:
        with self._lock:
            c = self._client
        assert c is not None, "no client connected"
        c.sendall(data)

    def kick(self) -> None:
        """Close the current client's connection (the server keeps listening)."""
        with self._lock:
            c = self._client
        if c is not None:
            c.shutdown(socket.SHUT_RDWR)

    def stop(self) -> None:
        self._running = False
        with self._lock:
            c = self._client
        for s in (c, self._listener):
            if s is not None:
                try:
                    s.close()
                except OSError:
                    pass
        if self._thread is not None:
            self._thread.join(2)
        self._listener = None

    def restart(self, down_for: float = 0.0) -> None:
        self.stop()
        time.sleep(down_for)
        self.start()

    def __enter__(self) -> TinyServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
