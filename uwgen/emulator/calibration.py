"""Replay real DESERT packet traces through the emulator core and compare the two.

A calibration trace (`<run>.jsonl` + `<run>.ns.txt`, see the README next to the traces)
records every write two TCP clients made to a real DESERT's two application sockets and
every chunk that came back, with timestamps.  `replay()` feeds the same writes, at the
same times and with the same bytes, into an `EmulatorCore` set up like the traced
scenario (distance, packet size, period, bit rate, the traced PHY), cuts the run where
DESERT's run ended (or crashed), and measures the same things on both sides:
delivered fraction per direction, latency distribution, and whether chunks merged.

    python -m uwgen.emulator.calibration [DIR]     # prints the real-vs-emulated table

The traces are measurements, found in $UWGEN_CALIBRATION_DIR or ../shared/calibration
next to the checkout; `find_trace_dir()` says where.
"""
from __future__ import annotations

import json
import os
import re
import statistics
import sys
from dataclasses import dataclass, field
from pathlib import Path

from uwgen.emulator.core import EmulatorCore
from uwgen.emulator.physics import DESERT_STOCK
from uwgen.emulator.scenario import NodeSpec, Scenario

SIDES = ("A", "B")
_TAGS = {b"A>": "A", b"B>": "B"}
_PARAM = re.compile(r"(\w+)=([-\w.+]+)")

# The traced PHY: DESERT's stock scenario's, the emulator's default (physics.DESERT_STOCK).
TRACE_PHY = DESERT_STOCK


def find_trace_dir() -> Path | None:
    """$UWGEN_CALIBRATION_DIR, else the first `shared/calibration` above this checkout."""
    env = os.environ.get("UWGEN_CALIBRATION_DIR")
    if env:
        return Path(env) if Path(env).is_dir() else None
    here = Path(__file__).resolve()
    for parent in here.parents:
        candidate = parent / "shared" / "calibration"
        if candidate.is_dir():
            return candidate
    return None


@dataclass
class Trace:
    name: str
    distance: float
    period: float                       # the application's send period (DESERT period_)
    end: float                          # when DESERT's run ended (exit or crash)
    crashed: bool
    writes: list = field(default_factory=list)   # (t, side, payload bytes)
    recvs: list = field(default_factory=list)    # (t, side, payload bytes)

    @property
    def pattern(self) -> str:
        """Repetitions of one pattern share it: P2, P2_rep2 and P2_short15 are all `P2`."""
        return re.sub(r"_(rep\d+|short\d+)$", "", self.name)


def load_trace(jsonl: Path) -> Trace:
    """Read `<run>.jsonl` and its `<run>.ns.txt` (parameters, exit)."""
    ns = jsonl.parent / (jsonl.name[:-len(".jsonl")] + ".ns.txt")
    params: dict[str, str] = {}
    exit_t: float | None = None
    crashed = False
    if ns.exists():
        for line in ns.read_text().splitlines():
            if line.startswith("params:"):
                params.update(_PARAM.findall(line))
            m = re.search(r"ns_rc:\s*(-?\d+)\s+ns_exit_t_since_ready:\s*([\d.]+)", line)
            if m:
                crashed = int(m.group(1)) != 0
                exit_t = float(m.group(2))
    events = [json.loads(line) for line in jsonl.read_text().splitlines() if line.strip()]
    # The application period is in the run's name (`_app1.0`) or its parameters; 0.2 s else.
    app = re.search(r"_app([\d.]+)", jsonl.name)
    period = float(params.get("app", params.get("app_period", params.get(
        "period", app.group(1) if app else 0.2))))
    last = max((e["t"] for e in events), default=0.0)
    tr = Trace(name=jsonl.name[:-len(".jsonl")], distance=float(params.get("dist", 300)),
               period=period, end=exit_t if exit_t is not None else last + 1.0,
               crashed=crashed)
    for e in events:
        item = (float(e["t"]), e["side"], bytes.fromhex(e["hex"]))
        (tr.writes if e["ev"] == "write" else tr.recvs).append(item)
    return tr


def load_traces(directory: Path) -> list[Trace]:
    return [load_trace(p) for p in sorted(Path(directory).glob("*.jsonl"))]


@dataclass
class Direction:
    """What one direction (writes on `side`, received on the other) came to."""

    writes: int = 0
    delivered: int = 0
    latencies: list = field(default_factory=list)
    chunks: int = 0          # received chunks
    merged: int = 0          # chunks holding more than one write, or part of one

    def add(self, other: "Direction") -> None:
        self.writes += other.writes
        self.delivered += other.delivered
        self.latencies += other.latencies
        self.chunks += other.chunks
        self.merged += other.merged

    @property
    def fraction(self) -> float:
        return self.delivered / self.writes if self.writes else 0.0

    @property
    def median_latency(self) -> float:
        return statistics.median(self.latencies) if self.latencies else float("nan")

    def latency_quantile(self, q: float) -> float:
        if not self.latencies:
            return float("nan")
        ordered = sorted(self.latencies)
        return ordered[round(q * (len(ordered) - 1))]


def _key(payload: bytes) -> tuple[str, int] | None:
    side = _TAGS.get(payload[:2])
    if side is None or len(payload) < 4:
        return None
    return side, int.from_bytes(payload[2:4], "big")


def _measure(writes: list, recvs: list) -> dict[str, Direction]:
    """Per writing side: writes, distinct writes received on the other side, latencies."""
    out = {s: Direction() for s in SIDES}
    written: dict[tuple[str, int], tuple[float, bytes]] = {}
    for t, side, data in writes:
        out[side].writes += 1
        k = _key(data)
        if k is not None:
            written[k] = (t, data)
    seen: set = set()
    for t, side, data in recvs:
        k = _key(data)
        src = k[0] if k else ("B" if side == "A" else "A")
        if src == side:
            continue                       # a node hearing its own write (seen once in P3)
        d = out[src]
        d.chunks += 1
        if k is None or k not in written or written[k][1] != data:
            d.merged += 1
            continue
        if k in seen:
            continue
        seen.add(k)
        d.delivered += 1
        d.latencies.append(t - written[k][0])
    return out


def measure_real(trace: Trace) -> dict[str, Direction]:
    return _measure(trace.writes, trace.recvs)


def scenario_for(trace: Trace, seed: int = 1, **overrides) -> Scenario:
    kw = dict(period=trace.period, max_read_length=64, bitrate=4800.0, seed=seed,
              listen_time=0.01, listen_jitter=0.01, snr=TRACE_PHY)
    kw.update(overrides)
    return Scenario(nodes=[NodeSpec("A", position=(0.0, 0.0, 100.0), dest="B"),
                           NodeSpec("B", position=(trace.distance, 0.0, 100.0), dest="A")],
                    **kw)


def replay(trace: Trace, seed: int = 1, **overrides) -> dict[str, Direction]:
    """The trace's writes through the emulator core, cut where DESERT's run ended."""
    core = EmulatorCore(scenario_for(trace, seed, **overrides))
    core.client_attached("A", 0.0)
    core.client_attached("B", 0.0)
    recvs = []
    for t, side, data in sorted(trace.writes, key=lambda w: w[0]):
        if t > trace.end:
            break
        core.client_data(side, t, data)
    for d in core.advance(trace.end):
        recvs.append((d.time, d.node, d.data))
    return _measure(trace.writes, recvs)


@dataclass
class Row:
    pattern: str
    side: str
    distance: float
    real: Direction
    emulated: Direction


def compare(traces: list[Trace], seeds: range = range(1, 33), **overrides) -> list[Row]:
    """One row per pattern, distance and direction with traffic: real pooled over
    repetitions, emulated pooled over repetitions and seeds."""
    rows: dict[tuple[str, str], Row] = {}
    for tr in traces:
        real = measure_real(tr)
        emus = [replay(tr, seed, **overrides) for seed in seeds]
        for side in SIDES:
            if not real[side].writes:
                continue
            row = rows.setdefault((tr.pattern, tr.distance, side),
                                  Row(tr.pattern, side, tr.distance, Direction(), Direction()))
            row.real.add(real[side])
            for e in emus:
                row.emulated.add(e[side])
    # Emulated writes were counted once per seed: the fraction is unaffected.
    return list(rows.values())


def table(rows: list[Row]) -> str:
    """The markdown table of docs/emulator.md."""
    def spread(d: Direction) -> str:
        return " / ".join(f"{d.latency_quantile(q):.3f}" for q in (0.1, 0.5, 0.9))

    lines = ["| pattern | direction | distance | real delivered | emulated delivered "
             "| real latency p10 / p50 / p90 (s) | emulated latency p10 / p50 / p90 (s) "
             "| merged chunks (real / emulated) |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        arrow = "A→B" if r.side == "A" else "B→A"
        lines.append(
            f"| {r.pattern} | {arrow} | {r.distance:.0f} m | {r.real.fraction:.3f} "
            f"| {r.emulated.fraction:.3f} | {spread(r.real)} | {spread(r.emulated)} "
            f"| {r.real.merged} / {r.emulated.merged} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    directory = Path(argv[0]) if argv else find_trace_dir()
    if directory is None or not directory.is_dir():
        print("no calibration traces found (give a directory or set UWGEN_CALIBRATION_DIR)",
              file=sys.stderr)
        return 2
    print(table(compare(load_traces(directory))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
