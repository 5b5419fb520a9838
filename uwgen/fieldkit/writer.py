"""A rotating MCAP file written from a thread of its own.

    out = RotatingMcap(Path("vehicle.mcap"), max_bytes=64 << 20, keep=4, metadata={...})
    ch = out.channel("/turtle1/pose", "cdr", schema=("turtlesim/msg/Pose", "ros2msg", text))
    out.add(ch, log_ns, data, publish_ns, sequence)      # any thread; never blocks, never raises
    out.close()                                           # the last file gets its summary

Callers only append to a queue (a tuple, no I/O, no lock held while writing); the thread
drains it every `tick` seconds, and ends the chunk in progress every `flush_every` seconds,
so a recording cut short (SIGKILL, power loss) loses at most that much: a reader reads it
up to its last complete chunk (uwgen.fieldkit.reader). A queue past `max_pending` records
(the disk far behind) drops new records, counted.

Size is bounded by rotation: when a file passes `max_bytes` it is finished (summary, footer)
and the next one is opened, `vehicle.1.mcap`, `vehicle.2.mcap`, ...; only the newest
`keep` files are kept (0: all). Each file has every schema, channel and metadata record it
needs, so it opens alone. An error writing (full disk) stops the recording with one log
line; the bridge goes on.
"""
from __future__ import annotations

import logging
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any, Callable

log = logging.getLogger("uwgen.record")

DEFAULT_MAX_BYTES = 64 * 1024 * 1024
DEFAULT_KEEP = 8
CHUNK_SIZE = 256 * 1024
FLUSH_EVERY = 1.0       # s: the most a recording cut short loses
TICK = 0.25             # s between drains of the queue
MAX_PENDING = 100_000   # records waiting for the writer thread


def rotated_name(path: Path, n: int) -> Path:
    """The n-th file of a recording: `x.mcap`, then `x.1.mcap`, `x.2.mcap`, ..."""
    return path if n == 0 else path.with_name(f"{path.stem}.{n}{path.suffix or '.mcap'}")


class RotatingMcap:
    def __init__(self, path: Path, *, max_bytes: int = DEFAULT_MAX_BYTES, keep: int = DEFAULT_KEEP,
                 metadata: dict[str, dict[str, str]] | None = None, profile: str = "ros2",
                 compression: str = "zstd", flush_every: float = FLUSH_EVERY, tick: float = TICK,
                 max_pending: int = MAX_PENDING, opener: Callable[[Path], Any] | None = None,
                 monotonic: Callable[[], float] = time.monotonic):
        from mcap.writer import CompressionType
        self.path = Path(path)
        self.max_bytes, self.keep = max_bytes, keep
        self.metadata = metadata or {}
        self.profile = profile
        self.compression = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                            "none": CompressionType.NONE}[compression]
        self.flush_every, self.tick, self.max_pending = flush_every, tick, max_pending
        self._open = opener or (lambda p: open(p, "wb"))
        self._monotonic = monotonic
        self._queue: deque = deque()
        self._channels: list[tuple[str, str, tuple[str, str, str] | None]] = []
        self._ids: dict[int, int] = {}       # our channel index -> id in the current file
        self.files: list[Path] = []
        self.counters = {"records": 0, "dropped": 0, "files": 0, "bytes": 0, "write_errors": 0}
        self._writer: Any = None
        self._stream: Any = None
        self._failed = False
        self._stop = threading.Event()
        self._lock = threading.Lock()        # channel registration vs the writer thread
        self._new_file()
        self._thread = threading.Thread(target=self._run, name="uwgen-record", daemon=True)
        self._thread.start()

    # -- any thread ---------------------------------------------------------------------

    def channel(self, topic: str, encoding: str, schema: tuple[str, str, str] | None = None) -> int:
        """A channel index for `add`: `schema` is (name, encoding, text) or None."""
        with self._lock:
            self._channels.append((topic, encoding, schema))
            return len(self._channels) - 1

    def add(self, channel: int, log_ns: int, data: bytes, publish_ns: int | None = None,
            sequence: int = 0) -> None:
        if self._failed:
            return
        if len(self._queue) >= self.max_pending:
            self.counters["dropped"] += 1
            return
        self._queue.append((channel, log_ns, data, log_ns if publish_ns is None else publish_ns,
                            sequence))

    def sync(self) -> None:
        """Write what is queued and end the chunk in progress now (the thread does it every
        `flush_every` seconds)."""
        with self._lock:
            self._drain()
            if not self._failed:
                self._guarded(self._flush)

    def close(self) -> None:
        """Write what is queued, finish the file (summary and footer). Idempotent."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=10.0)
        with self._lock:
            self._drain()
            self._finish()

    def stats(self) -> dict:
        return {**self.counters, "pending": len(self._queue), "failed": self._failed,
                "files": [str(p) for p in self.files]}

    # -- the writer thread ----------------------------------------------------------------

    def _run(self) -> None:
        last_flush = self._monotonic()
        while not self._stop.wait(self.tick):
            with self._lock:
                self._drain()
                if self._monotonic() - last_flush >= self.flush_every and not self._failed:
                    last_flush = self._monotonic()
                    self._guarded(self._flush)

    def _drain(self) -> None:
        while self._queue and not self._failed:
            channel, log_ns, data, publish_ns, seq = self._queue.popleft()
            self._guarded(self._write, channel, log_ns, data, publish_ns, seq)

    def _write(self, channel: int, log_ns: int, data: bytes, publish_ns: int, seq: int) -> None:
        cid = self._ids.get(channel)
        if cid is None:
            cid = self._ids[channel] = self._register(channel)
        self._writer.add_message(cid, log_ns, data, publish_ns, seq & 0xFFFFFFFF)
        self.counters["records"] += 1

    def _register(self, channel: int) -> int:
        topic, encoding, schema = self._channels[channel]
        sid = 0
        if schema is not None:
            sid = self._writer.register_schema(schema[0], schema[1], schema[2].encode())
        return self._writer.register_channel(topic, encoding, sid)

    def _flush(self) -> None:
        self._writer.flush()
        if self._stream.tell() >= self.max_bytes:
            self._finish()
            self._new_file()

    def _new_file(self) -> None:
        from mcap.writer import Writer
        path = rotated_name(self.path, len(self.files))
        self._stream = self._open(path)
        self.files.append(path)
        self.counters["files"] += 1
        self._writer = Writer(self._stream, chunk_size=CHUNK_SIZE, compression=self.compression)
        self._writer.start(profile=self.profile, library="uwgen")
        for name, data in self.metadata.items():
            self._writer.add_metadata(name, data)
        self._ids = {}
        if self.keep and len(self.files) > self.keep:
            old = self.files[-self.keep - 1]
            try:
                old.unlink()
            except OSError as exc:
                log.warning("recording: cannot remove old file %s: %s", old, exc)

    def _finish(self) -> None:
        if self._writer is None or self._failed:
            return
        try:
            self._writer.finish()
            self.counters["bytes"] += self._stream.tell()
            self._stream.close()
        except (OSError, ValueError) as exc:
            self._fail(exc)
        self._writer = None

    def _guarded(self, fn: Callable[..., None], *args: Any) -> None:
        try:
            fn(*args)
        except (OSError, ValueError) as exc:
            self._fail(exc)

    def _fail(self, exc: BaseException) -> None:
        self._failed = True
        self.counters["write_errors"] += 1
        self._queue.clear()
        log.error("recording to %s stopped: %s (the file is readable up to its last complete "
                  "chunk; the bridge goes on)", self.files[-1] if self.files else self.path, exc)
        try:
            self._stream.close()
        except (OSError, ValueError):
            pass
