"""The bridge's health on `/diagnostics` (diagnostic_msgs/DiagnosticArray), the ROS
convention rqt_robot_monitor, diagnostic_aggregator and Foxglove read.

One DiagnosticStatus for the bridge (`uwgen <network>/<side>`) and one per entry
(`uwgen <network>/<side> <topic|service|action> NAME`), judged from what ~/status counts
(docs/operators.md, "Diagnostics"):

- ERROR: the link to the DESERT node is down; an entry whose link is down is WARN;
- WARN, while it happens and for HOLD seconds after: drops since the last look (stale or
  expired messages, queue overflow, frames not authentic, payloads that did not decode,
  an executor that fell behind), a peer clock the receiver finds off, MAC turns missed or
  dropped (mode `turns`: the link's `mac` stats), a full queue, and a
  delivery ratio under DELIVERY_WARN over the copies the far side acknowledged or named
  lost since the last look (wire format 2; ERROR under DELIVERY_ERROR);
- OK otherwise. Every status carries its figures as key/value pairs.

`CHECKS` is the list of extra checks of the bridge's status: each takes the status dict and
returns (level, text) pairs. Pure except the
publisher: `Assessor` takes a clock and a status dict, so tests drive it without ROS.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

from uwgen.runtime.clock import SYSTEM_CLOCK, Clock

OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = ("OK", "WARN", "ERROR")
HOLD = 10.0             # s a WARN for drops lasts after the last one
DELIVERY_WARN = 0.5     # delivery ratio (acknowledged / settled) under which an entry warns
DELIVERY_ERROR = 0.1
MIN_SETTLED = 4         # copies settled since the last look before a ratio is judged

# Counters of an entry whose increase is a WARN, by where they are in its status entry.
ENTRY_DROPS = {
    "link": ("expired", "overflow", "too_large", "invalid", "protect_failed"),
    "": ("decode_errors", "encode_errors", "publish_errors", "refused", "timeouts", "late",
         "no_server", "server_timeouts", "accept_timeouts", "result_timeouts"),
    "on_link": ("stale",),
}
BRIDGE_DROPS = {("security", "dropped"): "frames dropped as not authentic",
                ("bridge", "inbox_overflow"): "payloads dropped: the executor fell behind",
                ("bridge", "bad_header"): "payloads with a bad header",
                ("reliability", "clock_offset"): "messages from a peer whose clock is off",
                ("reliability", "stale"): "stale messages dropped on arrival",
                ("connection", "reconnects"): "reconnects to the DESERT node",
                ("mac", "missed"): "MAC turns missed (a grant or an end lost, the turn taken back)",
                ("mac", "dropped_turns"): "MAC turns dropped (granted too late to use)",
                ("mac", "late_answers"): "MAC answers later than their turn's bound (the "
                                         "manifest's range or bitrate is not the real one)"}

Check = Callable[[dict], list[tuple[int, str]]]
CHECKS: list[Check] = []   # extra checks of the bridge's status (e.g. the MAC's turn health)


@dataclass
class Verdict:
    name: str
    level: int = OK
    texts: list[str] = field(default_factory=list)
    values: dict[str, str] = field(default_factory=dict)

    def worse(self, level: int, text: str) -> None:
        self.level = max(self.level, level)
        self.texts.append(text)

    @property
    def message(self) -> str:
        return "; ".join(self.texts) if self.texts else "OK"


class Assessor:
    """Status dicts in, verdicts out; remembers counts between looks for what is new."""

    def __init__(self, network: str, side: str, depths: dict[int, int] | None = None,
                 clock: Clock = SYSTEM_CLOCK, checks: list[Check] | None = None):
        self.prefix = f"uwgen {network}/{side}"
        self.depths = depths or {}
        self.clock = clock
        self.checks = CHECKS if checks is None else checks
        self._seen: dict[tuple, int] = {}
        self._warned: dict[tuple, tuple[float, str]] = {}   # key -> (until, text)

    def assess(self, status: dict) -> list[Verdict]:
        now = self.clock.now()
        link = status.get("link") if isinstance(status.get("link"), dict) else {}
        up = bool(link.get("connected"))
        bridge = Verdict(self.prefix)
        conn = link.get("connection") or {}
        bridge.values.update(connected=str(up), reconnects=str(conn.get("reconnects", 0)),
                             frames_sent=str(conn.get("frames_sent", 0)),
                             frames_received=str(conn.get("frames_received", 0)))
        if not up:
            bridge.worse(ERROR, "link down: not connected to the DESERT node")
        sections = {"security": status.get("security") or {}, "bridge": status.get("bridge") or {},
                    "reliability": link.get("reliability") or {}, "connection": conn,
                    "mac": link.get("mac") or {}}
        if sections["mac"].get("mode"):
            bridge.values["mac"] = str(sections["mac"]["mode"])
        for (section, counter), text in BRIDGE_DROPS.items():
            self._drops(bridge, (section, counter), sections[section].get(counter), text, now)
        for check in self.checks:
            for level, text in check(status):
                bridge.worse(level, text)
        verdicts = [bridge]
        for kind, entries in (("topic", status.get("topics")), ("service", status.get("services")),
                              ("action", status.get("actions"))):
            for name, entry in (entries or {}).items():
                verdicts.append(self._entry(kind, name, entry, up, now))
        return verdicts

    def _entry(self, kind: str, name: str, entry: dict, up: bool, now: float) -> Verdict:
        v = Verdict(f"{self.prefix} {kind} {name}")
        if entry.get("unavailable"):
            v.worse(ERROR, f"not bridged: {entry['unavailable']}")
            return v
        if not up:
            v.worse(WARN, "link down")
        link = entry.get("link") if isinstance(entry.get("link"), dict) else {}
        for where, counters in ENTRY_DROPS.items():
            counts = entry if where == "" else link if where == "link" else (link.get("on_link") or {})
            for counter in counters:
                self._drops(v, (v.name, where, counter), counts.get(counter), counter.replace("_", " "), now)
        queued, depth = link.get("queued"), self.depths.get(entry.get("id"))
        if isinstance(queued, int):
            v.values["queued"] = str(queued)
            if depth and depth > 1 and queued >= depth:
                v.worse(WARN, f"queue full ({queued} of {depth})")
        on_link = link.get("on_link")
        if isinstance(on_link, dict):
            self._delivery(v, on_link)
        return v

    def _drops(self, v: Verdict, key: tuple, value: Any, text: str, now: float) -> None:
        if not isinstance(value, int):
            return
        old = self._seen.get(key, 0)
        self._seen[key] = value
        if value > old:
            self._warned[key] = (now + HOLD, f"{value - old} {text}")
        held = self._warned.get(key)
        if held is not None and now < held[0]:
            v.worse(WARN, held[1])

    def _delivery(self, v: Verdict, ledger: dict) -> None:
        delivered, lost = int(ledger.get("delivered", 0)), int(ledger.get("lost_on_link", 0))
        d0 = self._seen.get((v.name, "delivered"), 0)
        l0 = self._seen.get((v.name, "lost"), 0)
        settled = (delivered - d0) + (lost - l0)
        if settled < MIN_SETTLED:
            return
        self._seen[(v.name, "delivered")], self._seen[(v.name, "lost")] = delivered, lost
        ratio = (delivered - d0) / settled
        v.values["delivery_ratio"] = f"{ratio:.2f}"
        if ratio < DELIVERY_ERROR:
            v.worse(ERROR, f"delivery ratio {ratio:.2f}")
        elif ratio < DELIVERY_WARN:
            v.worse(WARN, f"delivery ratio {ratio:.2f}")


class Diagnostics:
    """Publishes the Assessor's verdicts on /diagnostics (the bridge node's timer calls
    `publish` with its status every `diagnostics_period` seconds)."""

    def __init__(self, wiring: Any, network: str, side: str, depths: dict[int, int] | None = None):
        from diagnostic_msgs.msg import DiagnosticArray
        self.w = wiring
        self.assessor = Assessor(network, side, depths, clock=wiring.clock)
        self._cls = DiagnosticArray
        self._pub = wiring.node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.hardware_id = f"{network}/{side}"

    def publish(self, status: dict) -> Any:
        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
        msg = self._cls()
        msg.header.stamp = self.w.node.get_clock().now().to_msg()
        for v in self.assessor.assess(status):
            msg.status.append(DiagnosticStatus(
                level=bytes([v.level]), name=v.name, message=v.message, hardware_id=self.hardware_id,
                values=[KeyValue(key=k, value=val) for k, val in v.values.items()]))
        try:
            self._pub.publish(msg)
        except Exception:  # noqa: BLE001 - the context is shutting down
            pass
        return msg


class Watching:
    """The node's field kit: /diagnostics on a timer and the recording (with --record), both
    fed the node's status; `record` takes the ~/status timer's snapshots too."""

    def __init__(self, node: Any, wiring: Any, plan: Any, status: Callable[[], dict]):
        self.recorder = wiring.recorder
        self.status = status
        self.diagnostics = Diagnostics(wiring, plan.network, plan.side,
                                       {key: policy.depth for key, policy, _n, _w in plan.channels()})
        if self.recorder is not None and hasattr(node.link, "observers"):
            node.link.observers.append(self.recorder.packet)
        if wiring.options.diagnostics_period > 0:
            node.create_timer(wiring.options.diagnostics_period, self.tick,
                              callback_group=wiring.main_group)

    def tick(self) -> Any:
        status = self.status()
        self.record(status)
        return self.diagnostics.publish(status)

    def record(self, status: dict, final: bool = False) -> dict:
        """Record a status snapshot (when recording); returns it."""
        if self.recorder is not None:
            self.recorder.status(status, final=final)
        return status

    def close(self, status: dict) -> None:
        if self.recorder is not None:
            self.recorder.status(status, final=True)
            self.recorder.close()
