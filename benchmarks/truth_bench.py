#!/usr/bin/env python3
"""Truth benchmark: the age bound, restarts and clock offsets (docs/seams.md section 8,
docs/wire-format.md sections 15.5 and 15.7), on simulated time.

    .venv/bin/python benchmarks/truth_bench.py
    .venv/bin/python benchmarks/truth_bench.py --processes [--holds 10,44,64,130] [--domains 71,72,73,74]

Both sides run the real Link, reliability and (sealed rows) per-packet seal code over the
emulator's core (`uwgen.emulator.duplex`): 64 B every 0.5 s, 4800 bit/s, 300 m. Simulated
time, so a 130 s hold costs nothing; no timing is scaled.

1. Delay series: a command (max age 2 s) every 2 s one way, a best-effort topic every 1 s the
   other way (so each side measures the other's clock); from t = 8 s two of the command
   sender's packets are held H s and then released. Request path: the command goes a -> b;
   response path: b -> a. Per cell: commands delivered after their max age (`late`), delivered
   twice (`double`), refused (with the reason counted), and delivered in time. The mixed
   manifest row is the build's answer (a native command beside an rmw_desert entry is refused).
   Reference: the same run with this build's judgement replaced by the previous rule (a
   transit over 15 s read as a clock offset, the message judged by its age item alone).
2. Restarts: a sender of a reliable topic restarts after N packets and sends 30 more:
   messages of the new start delivered, lost silently (neither delivered nor counted).
3. Far restart: the receiver restarts mid-stream: the sender's ledger (sent = delivered +
   lost_on_link + in_flight + unacknowledged + unknown).
4. Clock offsets: the receiver's clock off by d: when its peer's offset is first measured,
   the figure +- error, commands delivered after that and refused (reason).

--processes: the delay series and the SIGKILL cases with real `uwgen bridge` processes over the
emulator (benchmarks/truth_processes.py; real time, about 15 minutes): per hold, path and link
(sealed and unsealed networks run side by side, each on two ROS domains), a service call
(timeout 4 s) and a goal (accept_timeout 4 s) made while everything reaching the vehicle
(request path) or the surface (response path) for 5 s is held H s; per cell what ran on the
vehicle (late: after the deadline; double), what the caller was told, what the calling bridge
learnt afterwards. Then the vehicle's bridge is SIGKILLed mid-goal (a 6 s goal) and started
again at once and after 10 s. The mixed manifest row is `uwgen build`'s answer.
"""
from __future__ import annotations

import argparse
import itertools
import sys
import tempfile
import threading
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from uwgen.emulator import NodeSpec, Scenario                              # noqa: E402
from uwgen.emulator.duplex import DuplexSim                               # noqa: E402
from uwgen.manifest.model import LinkPolicy                               # noqa: E402
from uwgen.runtime.clock import ManualClock                               # noqa: E402
from uwgen.runtime.delivery import staleness                              # noqa: E402
from uwgen.runtime.delivery.reliability import Reliability                # noqa: E402
from uwgen.runtime.link.hooks import join_hooks                         # noqa: E402
from uwgen.security.guard import GuardConfig                              # noqa: E402
from uwgen.security.packet_seal import PacketSeal                         # noqa: E402

PERIOD, WALL0, KEY = 0.5, 1_790_000_000.0, bytes(range(32))
MAX_AGE = 3.0             # above this link's round trip (~1.4 s): the strict bound takes about one
COMMAND = LinkPolicy(queue="fifo", depth=8)
RELIABLE = LinkPolicy(queue="fifo", depth=100, ttl=60.0, reliable=True)
BEST_EFFORT = LinkPolicy(queue="fifo", depth=100, ttl=30.0)


class Wall:
    def __init__(self, clock, offset=0.0):
        self.clock, self.offset = clock, offset

    def now(self):
        return WALL0 + self.clock.now() + self.offset


class OldRule(staleness.Staleness):
    """The rule this build replaces: a transit outside [-5, 15] s is taken for a clock offset
    and the message judged by its age item alone; no measured offset."""

    def judge(self, time24, age, max_age, wall, offset=None):
        if time24 is None:
            return staleness.Verdict(staleness.STALE if age > max_age + self.tolerance else None, age)
        transit = staleness.Freshness(self.tolerance).age(time24, wall)
        if -self.tolerance <= transit <= self.tolerance + self.max_transit:
            total = age + max(transit, 0.0)
            return staleness.Verdict(staleness.STALE if total > max_age + self.tolerance else None, total)
        return staleness.Verdict(staleness.STALE if age > max_age + self.tolerance else None, age)


def sim(sealed=False, offsets=None, old=False, reliable_ttl=60.0):
    scen = Scenario(nodes=[NodeSpec("a", position=(0, 0, 0), dest="b"),
                           NodeSpec("b", position=(300, 0, 0), dest="a")],
                    period=PERIOD, max_read_length=64, per=0.0, seed=3, bitrate=4800.0)
    clock = ManualClock()
    engines = {}
    seals = engines.setdefault("seals", {})
    epochs = (bytes([n % 256, n // 256]) * 3 for n in itertools.count(1))

    def hooks_for(side):
        me, peer = (1, 2) if side == "a" else (2, 1)
        wall = Wall(clock, (offsets or {}).get(side, 0.0))
        seal = None
        if sealed:
            config = GuardConfig("bench", me, {peer: "b" if side == "a" else "a"},
                                 {9: "sign", 4: "sign", 7: "sign"}, {}, max_ages={9: MAX_AGE})
            seal = seals[side] = PacketSeal(KEY, config, wall=wall, clock=clock, name=side,
                                            epoch_source=lambda: next(epochs))
        rel = engines[side] = Reliability(
            me, period=PERIOD, reliable={7: reliable_ttl}, max_ages={9: MAX_AGE}, wall=wall,
            name=side, max_read_length=64,
            other_overhead=0 if seal is None else seal.hooks().overhead,
            epoch_source=None if sealed else (lambda: next(epochs)), clock_exchange=not old)
        if seal is not None and not old:
            seal.use_offsets(rel.offsets.of)                   # as the bridge wires them
        if old:
            rel.judge.staleness = OldRule()
            rel.offsets.reported = lambda *a, **k: None          # no exchange measured
        return join_hooks(rel.hooks(), seal.hooks() if seal else None)
    s = DuplexSim(scen, ("a", "b"), hooks_for=hooks_for, wire_format=2, clock=clock)
    return s, engines


def delay_cell(hold, path, sealed, old=False):
    s, rel = sim(sealed, old=old)
    src, dst = ("a", "b") if path == "request" else ("b", "a")
    s.links[src].add_channel(9, COMMAND)
    s.links[dst].add_channel(4, BEST_EFFORT)
    count = 20
    for i in range(count):
        s.at(i * 2.0, lambda i=i: s.links[src].offer(9, bytes((2, 9, i, 0xF5))))
    for i in range(int(count * 2 + hold + 20)):
        s.at(i + 0.5, lambda i=i: s.links[dst].offer(4, bytes((0, 4, i % 256))))
    s.run(8.0)
    n = s.written[src]
    s.hold(src, hold, n, n + 1)
    s.run(count * 2.0 + hold + 15)
    got = [(t, p[2]) for t, p in s.received[dst] if p[1] == 9]
    late = sum(1 for t, i in got if t - 2.0 * i > MAX_AGE)
    double = len(got) - len({i for _, i in got})
    c = rel[dst].counters
    refused = {k: c[k] for k in ("stale", "unexplained_delay", "clock_offset") if c[k]}
    seal = rel["seals"].get(dst)
    if seal is not None and seal.counters["stale"]:
        refused["seal: stale packets"] = seal.counters["stale"]
    return late, double, len(got) - late, refused


def restart_cell(after, sealed):
    s, rel = sim(sealed)
    s.links["a"].add_channel(7, RELIABLE)
    s.links["b"].add_channel(4, BEST_EFFORT)
    end = after * PERIOD + 5.0
    for i in range(int(end + 60)):
        s.at(i + 0.25, lambda i=i: s.links["b"].offer(4, bytes((0, 4, i % 256))))
    for i in range(after):
        s.at(i * PERIOD, lambda i=i: s.links["a"].offer(7, bytes((0, 7, 1, i)) + bytes(6)))
    s.run(end)
    s.restart("a").add_channel(7, RELIABLE)
    for i in range(30):
        s.at(end + 1 + i * PERIOD, lambda i=i: s.links["a"].offer(7, bytes((0, 7, 2, i)) + bytes(6)))
    s.run(end + 1 + 30 * PERIOD + 20)
    got = {p[3] for _, p in s.received["b"] if p[1] == 7 and p[2] == 2}
    row = rel["a"].ledger()[7]
    counted = row["lost_on_link"] + row["expired"] + row["in_flight"] + row["unacknowledged"]
    return len(got), 30 - len(got) - min(counted, 30 - len(got)), rel["b"].counters["restarts_seen"]


def far_restart(sealed):
    s, rel = sim(sealed)
    s.links["a"].add_channel(7, RELIABLE)
    s.links["b"].add_channel(4, BEST_EFFORT)
    for i in range(60):
        s.at(i * PERIOD, lambda i=i: s.links["a"].offer(7, bytes((0, 7, 1, i)) + bytes(6)))
    s.run(10.0)
    s.restart("b").add_channel(4, BEST_EFFORT)
    for i in range(60):
        s.at(10.25 + i, lambda i=i: s.links["b"].offer(4, bytes((0, 4, i))))
    s.run(80.0)
    return rel["a"].ledger()[7]


def offset_cell(d, sealed=False):
    s, rel = sim(sealed, offsets={"b": d})
    s.links["a"].add_channel(9, COMMAND)
    s.links["b"].add_channel(4, BEST_EFFORT)
    for i in range(OFFSET_COMMANDS):
        s.at(i * 2.0, lambda i=i: s.links["a"].offer(9, bytes((2, 9, i, 0xF5))))
    for i in range(2 * OFFSET_COMMANDS + 6):
        s.at(i + 0.5, lambda i=i: s.links["b"].offer(4, bytes((0, 4, i))))
    s.run(2.0 * OFFSET_COMMANDS + 5)
    first = rel["b"].first_offset_at.get(1)
    o = rel["b"].offsets.of(1)
    after = [p for t, p in s.received["b"] if p[1] == 9 and first is not None and t > first]
    c = rel["b"].counters
    refused = {k: c[k] for k in ("clock_offset", "unexplained_delay", "stale") if c[k]}
    seal = rel["seals"].get("b")
    if seal is not None and seal.counters["stale"]:
        refused["seal: stale packets"] = seal.counters["stale"]
    delivered = sum(1 for _, p in s.received["b"] if p[1] == 9)
    return first, o, len(after), delivered, refused


OFFSET_COMMANDS = 30      # one every 2 s: a sealed link hears a clock d behind only d s after start


def main() -> int:
    print(f"1. Delay series: commands (max age {MAX_AGE:g} s), two packets held H s (0 late and 0 double wanted)")
    print(f"{'hold s':>6} {'path':>8} {'link':>8} | {'late':>4} {'double':>6} {'in time':>7}  refused"
          f"   || reference (previous rule): late")
    for hold in (10, 44, 64, 130):
        for path in ("request", "response"):
            for sealed in (False, True):
                late, double, ok, refused = delay_cell(hold, path, sealed)
                ref = delay_cell(hold, path, sealed, old=True)[0] if not sealed else "-"
                print(f"{hold:>6} {path:>8} {'sealed' if sealed else 'unsealed':>8} | {late:>4} "
                      f"{double:>6} {ok:>7}  {refused}   || {ref}")
    print(f"{'any':>6} {'any':>8} {'mixed':>8} | refused at build: a native service or action "
          "beside an rmw_desert entry (located error)")
    print()
    print("2. Sender restarted after N packets, then 30 reliable messages (0 lost silently wanted)")
    print(f"{'N':>4} {'link':>8} | {'delivered':>9} {'lost silently':>13} {'restarts seen':>13}")
    for after in (5, 20, 200):
        for sealed in (False, True):
            got, silent, seen = restart_cell(after, sealed)
            print(f"{after:>4} {'sealed' if sealed else 'unsealed':>8} | {got:>6}/30 {silent:>13} {seen:>13}")
    print()
    print("3. Far restart mid-stream: the sender's ledger of its reliable topic")
    for sealed in (False, True):
        row = far_restart(sealed)
        closes = row["sent"] == (row["delivered"] + row["lost_on_link"] + row["in_flight"]
                                 + row["unacknowledged"] + row["unknown"])
        print(f"  {'sealed' if sealed else 'unsealed':>8}: sent {row['sent']} delivered "
              f"{row['delivered']} lost_on_link {row['lost_on_link']} unknown {row['unknown']} "
              f"in_flight {row['in_flight']}: {'exact' if closes else 'DOES NOT CLOSE'}")
    print()
    print(f"4. Receiver's clock off by d (tolerance 5 s), {OFFSET_COMMANDS} commands: the peer's offset as measured")
    print(f"{'d s':>5} {'link':>8} | {'measured at s':>13} {'offset':>8} {'+-':>5} | "
          f"{'delivered':>9} {'after it':>8}  refused")
    for sealed in (False, True):
        for d in (3, -3, 6, -6, 30, -30):
            first, o, after, delivered, refused = offset_cell(float(d), sealed)
            figures = (f"{first:>13.2f} {o.offset:>8.2f} {o.error:>5.2f}" if o is not None
                       else f"{'never':>13} {'-':>8} {'-':>5}")
            print(f"{d:>5} {'sealed' if sealed else 'unsealed':>8} | {figures} | {delivered:>9} "
                  f"{after:>8}  {refused}")
    return 0


def processes(holds: list[float], domains: list[int]) -> int:
    import truth_processes as tp
    root = Path(tempfile.mkdtemp(prefix="truth-processes-"))
    rows: dict[str, list] = {"unsealed": [], "sealed": []}
    kills: dict[str, list] = {"unsealed": [], "sealed": []}
    errors: list[str] = []

    def series(link: str, pair: tuple[int, int]) -> None:
        try:
            with tp.Network(root / link, sealed=link == "sealed", domains=pair) as net:
                net.ready()
                ident = 1
                for hold in holds:
                    for path in ("request", "response"):
                        rows[link].append(tp.delay_cell(net, ident, hold, path, settle=10.0))
                        ident += 1
                net.vehicle.goal_seconds = 6.0
                for down in (0.0, 10.0):
                    kills[link].append(tp.kill_cell(net, 100 + int(down), down))
        except Exception as exc:  # noqa: BLE001 - reported in the table
            errors.append(f"{link}: {exc!r}")

    threads = [threading.Thread(target=series, args=(link, (domains[2 * i], domains[2 * i + 1])))
               for i, link in enumerate(("unsealed", "sealed"))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    print("Delay series with real bridge processes (call timeout 4 s, goal accept_timeout 4 s;")
    print("everything reaching the vehicle (request) or the surface (response) for 5 s held H s)")
    print(f"{'hold s':>6} {'path':>8} {'link':>8} | {'late':>4} {'double':>6} | {'call ran':>8} "
          f"{'caller told':>12} {'bridge learnt':>20} | {'goal ran':>8} {'caller told':>11} | match")
    for link in ("unsealed", "sealed"):
        for c in rows[link]:
            learnt = ",".join(f"{k}" for k in c.learnt) or "-"
            print(f"{c.hold:>6g} {c.path:>8} {link:>8} | {c.late():>4} {c.double():>6} | "
                  f"{len(c.call_ran):>8} {c.call_told:>12} {learnt:>20} | {len(c.goal_ran):>8} "
                  f"{c.goal_told:>11} | {'yes' if c.matches() else 'NO'}")
    code, error = tp.mixed_build(root / "mixed")
    print(f"{'any':>6} {'any':>8} {'mixed':>8} | uwgen build exit {code}: {error}")
    print()
    print("SIGKILL of the vehicle's bridge mid-goal (a 6 s goal), started again after D s")
    print(f"{'D s':>4} {'link':>8} | {'running when killed':>19} {'ran':>3} {'caller told':>11} "
          f"{'left running unsupervised':>25}")
    for link in ("unsealed", "sealed"):
        for k in kills[link]:
            print(f"{k['down']:>4g} {link:>8} | {str(k['running when killed']):>19} {k['ran']:>3} "
                  f"{k['told']:>11} {k['left running']:>25}")
    for e in errors:
        print("ERROR", e)
    print(f"(logs and status files in {root})")
    return 1 if errors else 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--processes", action="store_true",
                        help="the delay series and SIGKILL cases with real bridge processes")
    parser.add_argument("--holds", default="10,44,64,130", help="hold seconds (--processes)")
    parser.add_argument("--domains", default="71,72,73,74",
                        help="four ROS domain ids: unsealed surface, vehicle, sealed surface, vehicle")
    a = parser.parse_args()
    if a.processes:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        sys.exit(processes([float(h) for h in a.holds.split(",")],
                           [int(d) for d in a.domains.split(",")]))
    sys.exit(main())
