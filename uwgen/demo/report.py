"""The demo's closing report: a table per topic and service, and the path plot.

Inputs are the demo's output folder: `operator.jsonl` and `vehicle.jsonl` (event records
of the two applications, see records.py), `bridge_<side>.json` (each bridge's final
status) and `emulator.json` (the emulated DESERT nodes' counters).

The table's columns are explained in uwgen.fieldkit.table (shared with `uwgen log`).
Under the tables, per side, the secure link's counts (the `security` entry of the bridge's
status): frames protected, frames verified, frames dropped as not authentic, by reason.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from uwgen.demo.pathplot import path_figure, plot_paths  # noqa: F401 - the demo's names
from uwgen.demo.records import read_records
from uwgen.demo.sizes import FrameSize, frame_sizes  # noqa: F401 - the demo's names
from uwgen.fieldkit.table import (Row, ServiceRow, format_tables, latencies_by_key,  # noqa: F401
                                  percentile, topic_row)
from uwgen.runtime.link.pacing import PACKET_HEADER
from uwgen.runtime.link.scheduler import DROP_REASONS


@dataclass
class Report:
    topics: list[Row]
    services: list[ServiceRow]
    commanded: list[tuple[float, float]]
    reported: list[tuple[float, float]]
    truth: list[tuple[float, float]]
    deviation_mean: float | None
    deviation_max: float | None
    end_error: float | None
    emulator: dict
    missions: list[dict] = field(default_factory=list)   # the operator's action goals
    sizes: list["FrameSize"] = field(default_factory=list)
    security: dict[str, dict] = field(default_factory=dict)   # side -> its bridge's security counts
    air: dict[str, tuple[int, int]] = field(default_factory=dict)   # side -> (air bytes, packets)
    wire_format: int | None = None
    action_links: dict[str, dict] = field(default_factory=dict)   # action -> its link ledger rows

    @property
    def messages_delivered(self) -> int:
        """Topic messages delivered, both payloads of each answered call, and each mission's
        goal, answer, feedback and result."""
        return (sum(r.delivered for r in self.topics) + sum(2 * s.ok for s in self.services)
                + sum(3 + int(m.get("feedback", 0)) for m in self.missions))

    @property
    def air_per_message(self) -> float | None:
        n = self.messages_delivered
        return sum(b for b, _ in self.air.values()) / n if n and self.air else None



# The grid of the demo manifest's /turtle1/pose field encodings (tests/bridge checks they
# agree): a published pose and the one received match when they round to the same point.
POSE_KEY_STEPS = (("x", 0.01), ("y", 0.01), ("theta", 0.001), ("v", 0.01), ("w", 0.01))

def _load_json(path: Path) -> dict:
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return {}



def build_report(out_dir: Path, side: str = "vehicle", namespace: str = "") -> Report:
    """The demo's report from its records; in a fleet, of the vehicle `side` whose names are
    under `namespace` (its records are operator_<side>.jsonl and vehicle_<side>.jsonl)."""
    out_dir = Path(out_dir)
    own = "" if side == "vehicle" else f"_{side}"
    ns = namespace.rstrip("/")
    op = list(read_records(out_dir / f"operator{own}.jsonl"))
    veh = list(read_records(out_dir / f"vehicle{own}.jsonl"))
    surface = _load_json(out_dir / "bridge_surface.json")
    vehicle = _load_json(out_dir / f"bridge_{side}.json")
    emulator = _load_json(out_dir / "emulator.json")

    def ev(records, name):
        return [r for r in records if r.get("ev") == name]

    rows = []
    cmd = topic_row(f"{ns}/turtle1/cmd_vel", "surface → vehicle", surface, vehicle)
    cmd.published = len(ev(op, "cmd"))
    cmd.delivered = len(ev(veh, "cmd"))
    cmd.latencies = latencies_by_key(((r["k"], r["t"]) for r in ev(op, "cmd")),
                                      ((r["k"], r["t"]) for r in ev(veh, "cmd")))
    rows.append(cmd)

    def pose_key(r):
        return tuple(round(r[k] / step) for k, step in POSE_KEY_STEPS)
    pose = topic_row(f"{ns}/turtle1/pose", "vehicle → surface", vehicle, surface)
    pose.published = len(ev(veh, "pose"))
    pose.delivered = len(ev(op, "pose_rx"))
    pose.latencies = latencies_by_key(((pose_key(r), r["t"]) for r in ev(veh, "pose")),
                                       ((pose_key(r), r["t"]) for r in ev(op, "pose_rx")))
    rows.append(pose)

    bat = topic_row(f"{ns}/vehicle/battery", "vehicle → surface", vehicle, surface)
    bat.published = len(ev(veh, "battery"))
    bat.delivered = len(ev(op, "battery_rx"))
    bat.latencies = [r["t"] - r["stamp"] for r in ev(op, "battery_rx")]
    rows.append(bat)

    logrow = topic_row(f"{ns}/vehicle/log", "vehicle → surface", vehicle, surface)
    logrow.published = len(ev(veh, "log"))
    logrow.delivered = len(ev(op, "log_rx"))
    logrow.latencies = latencies_by_key(((r["seq"], r["t"]) for r in ev(veh, "log")),
                                         ((r["seq"], r["t"]) for r in ev(op, "log_rx")))
    rows.append(logrow)

    services = []
    for name in (f"{ns}/vehicle/set_pen", f"{ns}/turtle1/teleport_absolute"):
        srow = ServiceRow(name)
        calls = [r for r in ev(op, "call") if r.get("name") == name]
        srow.calls = len(calls)
        srow.ok = sum(1 for r in calls if r["ok"])
        srow.failed = srow.calls - srow.ok
        srow.rtts = [r["rtt"] for r in calls if r["ok"]]
        for side in (surface, vehicle):
            link = side.get("services", {}).get(name, {}).get("link", {}) or {}
            srow.policy += sum(int(link.get(r, 0)) for r in DROP_REASONS)
            exact = link.get("on_link")
            if isinstance(exact, dict) and "lost_on_link" in exact:
                srow.lost_on_link = (srow.lost_on_link or 0) + int(exact["lost_on_link"])
        services.append(srow)
    action_links: dict[str, dict] = {}
    for side_name, side in (("surface", surface), ("vehicle", vehicle)):
        for name, entry in (side.get("actions") or {}).items():
            exact = (entry.get("link") or {}).get("on_link")
            if isinstance(exact, dict) and "sent" in exact:
                action_links.setdefault(name, {})[side_name] = exact

    commanded, reported, truth = paths(op, veh)
    dev = deviations(commanded, reported)
    end_error = None
    if commanded and truth:
        end_error = math.dist(commanded[-1], truth[-1])
    security = {side: status["security"] for side, status in (("surface", surface), ("vehicle", vehicle))
                if isinstance(status.get("security"), dict)}
    air, wire = {}, None
    for side, status in (("surface", surface), ("vehicle", vehicle)):
        link = status.get("link") or {}
        conn = link.get("connection") or {}
        if "bytes_sent" in conn:
            # what DESERT puts on the water: the bytes written, plus its 4-byte header a packet
            air[side] = (int(conn["bytes_sent"]) + PACKET_HEADER * int(conn.get("writes", 0)),
                         int(conn.get("writes", 0)))
            wire = link.get("wire_format", wire)
    return Report(rows, services, commanded, reported, truth,
                  (sum(dev) / len(dev)) if dev else None, max(dev) if dev else None,
                  end_error, emulator, ev(op, "mission"), security=security, air=air,
                  wire_format=wire, action_links=action_links)


def paths(op: list[dict], veh: list[dict]):
    """Commanded path (the operator's waypoints from the start pose; without waypoints, its
    commands integrated from the start pose), the poses the surface received, and the
    vehicle's own poses, all after the teleport."""
    start = next((r for r in op if r.get("ev") == "start"), None)
    if start is None:
        return [], [], []
    x, y, th = start["x"], start["y"], start["theta"]
    cmds = [r for r in op if r.get("ev") == "cmd" and r["t"] >= start["t"]]
    commanded = [(x, y)]
    if start.get("waypoints"):
        commanded += [tuple(w) for w in start["waypoints"]]
        cmds = []
    for a, b in zip(cmds, cmds[1:]):
        dt = b["t"] - a["t"]
        th += a["ang"] * dt
        x += a["lin"] * math.cos(th) * dt
        y += a["lin"] * math.sin(th) * dt
        commanded.append((x, y))
    teleported = next((r["t"] for r in veh if r.get("ev") == "teleport"), start["t"])
    reported = [(r["x"], r["y"]) for r in op if r.get("ev") == "pose_rx" and r["t"] >= start["t"]]
    truth = [(r["x"], r["y"]) for r in veh if r.get("ev") == "pose" and r["t"] >= teleported]
    return commanded, reported, truth


def deviations(commanded: list[tuple[float, float]], reported: list[tuple[float, float]]) -> list[float]:
    """Distance from each reported point to the commanded polyline."""
    if len(commanded) < 2:
        return []
    out = []
    for p in reported:
        out.append(min(_segment_distance(p, a, b) for a, b in zip(commanded, commanded[1:])))
    return out


def _segment_distance(p, a, b) -> float:
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    n = dx * dx + dy * dy
    t = 0.0 if n == 0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / n))
    return math.dist(p, (ax + t * dx, ay + t * dy))



def format_report(report: Report) -> str:
    lines = format_tables(report.topics, report.services)
    lines.append("")
    for m in report.missions:
        turned = m.get("status") == "succeeded" and m.get("delta") is not None
        lines.append(f"action {m.get('name')}: {m.get('status')} after {m.get('rtt', 0):.2f} s, "
                     f"{m.get('feedback', 0)} feedback messages"
                     + (f", turned {m['delta']:.2f} rad" if turned else ""))
    for name, sides in sorted(report.action_links.items()):
        lines.append(f"action {name} on the link: " + "; ".join(
            f"{side} sent {row['sent']}, delivered {row['delivered']}, lost {row['lost_on_link']}"
            + (f", in flight {row['in_flight']}" if row.get("in_flight") else "")
            for side, row in sorted(sides.items())))
    if report.deviation_mean is not None:
        lines.append(f"path: the poses the surface received stay within {report.deviation_max:.2f} m "
                     f"of the commanded square (mean {report.deviation_mean:.2f} m)"
                     + (f"; the vehicle ended {report.end_error:.2f} m from the commanded end point"
                        if report.end_error is not None else ""))
    if report.sizes:
        lines.append("frame sizes (one representative message): "
                     + "; ".join(_size(z) for z in report.sizes))
    if report.air_per_message is not None:
        lines.append(f"air bytes per delivered message: {report.air_per_message:.1f} "
                     f"({report.messages_delivered} messages; "
                     + "; ".join(f"{side} sent {b} B in {n} packets" for side, (b, n) in sorted(report.air.items()))
                     + f"; wire format {report.wire_format or 1}, DESERT's 4-byte packet header "
                       "included, announcements and security amortized)")
    if report.security:
        lines.append("security: " + "; ".join(_security(side, c) for side, c in sorted(report.security.items())))
    emu = report.emulator.get("nodes", {})
    for name, c in sorted(emu.items()):
        lost = {k: v for k, v in c.items() if k.startswith("lost_") and v}
        lines.append(f"DESERT node {name}: sent {c.get('packets_sent', 0)} packets, received "
                     f"{c.get('packets_delivered', 0)}"
                     + (f"; lost on the way to it: {', '.join(f'{k[5:]} {v}' for k, v in sorted(lost.items()))}"
                        if lost else ""))
    return "\n".join(lines)


def _size(z: FrameSize) -> str:
    if not z.security_bytes:
        return f"{z.topic} {z.sent} B with {z.how} (native {z.native} B)"
    return (f"{z.topic} {z.sent} B = {z.sent - z.security_bytes} B with {z.how} + {z.security_bytes} B "
            f"{z.security} (native, unprotected: {z.native} B)")


def _security(side: str, c: dict) -> str:
    from uwgen.security.guard import DROP_REASONS as SECURITY_DROPS
    reasons = {r: c[r] for r in SECURITY_DROPS if c.get(r)}
    return (f"{side} protected {c.get('protected', 0)} verified {c.get('verified', 0)} dropped "
            f"{c.get('dropped', 0)}" + (f" ({', '.join(f'{r} {n}' for r, n in reasons.items())})"
                                       if reasons else ""))

