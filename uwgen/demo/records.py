"""Event records of the demo's nodes: one JSON object per line, with a wall-clock time.

Every demo process runs on the same machine, so `time.time()` stamps taken in different
processes compare directly; the report matches what one side sent with what the other
received to measure latency. A message received from the link is recorded at the time
the far bridge published it (`delivered_at`: the message's source timestamp, stamped by
that bridge's rmw), not when the application's executor got round to it: the latency is
the link's, the same as `uwgen log` reads from the bridges' recordings, however busy the
machine. Values that cross the link as float32 are recorded as float32 (`f32`), so a sent
pose and a received pose compare exactly.
"""
from __future__ import annotations

import json
import struct
import threading
import time
from pathlib import Path
from typing import IO, Any, Iterator

from uwgen.runtime.clock import source_time


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", float(x)))[0]


# When the bridge that delivered a received message published it: its source timestamp
# (None without one: the record then takes now)
delivered_at = source_time


class Recorder:
    """Append-only JSON-lines writer (thread-safe, flushed per line; None path: no-op)."""

    def __init__(self, path: Path | None):
        self._fh: IO[str] | None = None
        self._lock = threading.Lock()
        if path is not None:
            path = Path(path)
            path.parent.mkdir(parents=True, exist_ok=True)
            self._fh = path.open("w", encoding="utf-8")

    def __call__(self, ev: str, at: float | None = None, **fields: Any) -> None:
        """Record event `ev` at time `at` (seconds since the epoch; now when None)."""
        if self._fh is None:
            return
        t = time.time() if at is None else at
        line = json.dumps({"t": t, "ev": ev, **fields}, separators=(",", ":"))
        with self._lock:
            self._fh.write(line + "\n")
            self._fh.flush()

    def close(self) -> None:
        with self._lock:
            if self._fh is not None:
                self._fh.close()
                self._fh = None


def read_records(path: Path) -> Iterator[dict]:
    """Records of a file; a torn last line (process killed mid-write) is skipped."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        return
    for line in text.splitlines():
        try:
            yield json.loads(line)
        except json.JSONDecodeError:
            continue
