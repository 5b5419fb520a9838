"""DESERT crashing at random, on purpose: bridges must survive their DESERT dying at any moment.

Real DESERT 4.0.0 aborted (an ns-2 assertion) in most runs with sustained two-way traffic,
after 4 to 42 s (../shared/calibration/README.md). The emulator itself does not crash;
`Crasher` makes it behave as if it did, so that a bridge, a demo or a test can be run
against that: at random instants (exponential, mean `every` seconds, seeded) it restarts
the emulator (every client disconnected, queues and packets in flight lost), and DESERT is
back `down` seconds later.

    with run_emulator(scen) as emu, Crasher(emu, every=20.0, down=2.0, seed=1):
        ...
    uwgen emulate -m uwgen.yaml --crash-every 20 --crash-down 2
"""
from __future__ import annotations

import logging
import random
import threading

log = logging.getLogger("uwgen.emulator")


class Crasher:
    """Restarts `emu` at random (see module doc); start()/stop() or use as a context manager."""

    def __init__(self, emu, every: float, down: float = 1.0, seed: int = 1):
        if not every > 0:
            raise ValueError(f"crash interval must be > 0 s, got {every!r}")
        if not down >= 0:
            raise ValueError(f"crash down time must be >= 0 s, got {down!r}")
        self.emu, self.every, self.down = emu, float(every), float(down)
        self.rng = random.Random(f"{seed}/crash")
        self.crashes = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> "Crasher":
        self._thread = threading.Thread(target=self._run, name="uwgen-crasher", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self.rng.expovariate(1.0 / self.every)):
            self.crashes += 1
            log.info("emulator: DESERT crashes (simulated, %d so far); back in %.2f s",
                     self.crashes, self.down)
            try:
                self.emu.restart(delay=self.down, wait=True)
            except Exception:  # noqa: BLE001 - the emulator was stopped under us
                return

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=self.down + 5.0)

    def __enter__(self) -> "Crasher":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
