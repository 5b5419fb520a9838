"""The demo's closing report: a table per topic and service, and the path plot.

Inputs are the demo's output folder: `operator.jsonl` and `vehicle.jsonl` (event records
of the two applications, see records.py), `bridge_<side>.json` (each bridge's final
status) and `emulator.json` (the emulated DESERT nodes' counters).

Columns, per topic (from the publishing side to the other):
  published  messages the application published
  taken      messages the sending bridge received from its local graph
  sub drop   messages its local subscription reported lost before the bridge took them
  on link    messages the sending link put on the wire (whole or in fragments)
  policy     messages dropped by policy (superseded, overflow, expired, too large, encode
             errors, echo guard), by reason in the bridges' status (`accounting`)
  lost       messages put on the wire that the far bridge never received (packet loss);
             (seen N): of those, N the link knows were lost (named by acknowledgements,
             or fragmented messages that never completed), never more than lost
  delivered  messages the far application received
  latency    from publication to delivery (median and 95th percentile), matched per message
So `taken = on link + policy + still queued`, and `on link = received by the far bridge + lost`
(uwgen.bridge.ledger); a topic whose bridge counters do not add up is named under the table.
Under the tables, per side, the secure link's counts (the `security` entry of the bridge's
status): frames protected, frames verified, frames dropped as not authentic, by reason.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from statistics import median
from typing import Iterable

from uwgen.bridge import ledger
from uwgen.demo.records import read_records
from uwgen.runtime.link.pacing import PACKET_HEADER
from uwgen.runtime.link.scheduler import DROP_REASONS


def percentile(values: list[float], q: float) -> float | None:
    """Linear-interpolated percentile (q in 0..100), None for no values."""
    if not values:
        return None
    s = sorted(values)
    pos = (len(s) - 1) * q / 100.0
    lo, hi = math.floor(pos), math.ceil(pos)
    return s[lo] + (s[hi] - s[lo]) * (pos - lo)


@dataclass
class Row:
    name: str
    direction: str
    published: int = 0
    taken: int = 0
    on_link: int = 0
    policy: int = 0
    queued: int = 0
    lost: int = 0
    lost_seen: int = 0
    sub_dropped: int = 0
    delivered: int = 0
    imbalances: list[str] = field(default_factory=list)
    latencies: list[float] = field(default_factory=list)

    @property
    def p50(self) -> float | None:
        return median(self.latencies) if self.latencies else None

    @property
    def p95(self) -> float | None:
        return percentile(self.latencies, 95)


@dataclass
class ServiceRow:
    name: str
    calls: int = 0
    ok: int = 0
    failed: int = 0
    policy: int = 0
    lost_on_link: int | None = None   # copies the sending links' acks name lost (wire format 2)
    rtts: list[float] = field(default_factory=list)


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


@dataclass(frozen=True)
class FrameSize:
    """Bytes on the wire of one representative message of a topic."""
    topic: str
    native: int            # frame bytes in profile native without field encodings, unprotected
    sent: int              # frame bytes as the manifest sends it (security included)
    how: str               # 'packed + field encodings', ...
    security: str = "off"  # sign | encrypt | off
    security_bytes: int = 0   # of `sent`, what the secure link adds (sync frames: 13 more)


# The grid of the demo manifest's /turtle1/pose field encodings (tests/bridge checks they
# agree): a published pose and the one received match when they round to the same point.
POSE_KEY_STEPS = (("x", 0.01), ("y", 0.01), ("theta", 0.001), ("v", 0.01), ("w", 0.01))


def _load_json(path: Path) -> dict:
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return {}


def _latencies_by_key(sent: Iterable[tuple[object, float]], received: Iterable[tuple[object, float]]) -> list[float]:
    """For each received (key, t), the delay since the send of the same key. Keys sent more
    than once (a vehicle standing still publishes the same pose again and again) are
    ambiguous and left out rather than guessed."""
    by_key: dict[object, list[float]] = {}
    for key, t in sent:
        by_key.setdefault(key, []).append(t)
    out = []
    for key, t in received:
        times = by_key.get(key, ())
        if len(times) == 1 and times[0] <= t:
            out.append(t - times[0])
    return out


def _topic_row(name: str, direction: str, sender: dict, receiver: dict) -> Row:
    row = Row(name, direction)
    out = sender.get("topics", {}).get(name, {})
    inc = receiver.get("topics", {}).get(name, {})
    link = out.get("link", {}) or {}
    if "accounting" in out and "accounting" in inc:
        acc, rx = out["accounting"], inc["accounting"]
        row.taken, row.sub_dropped = acc["taken"], acc["dropped_by_subscription"]
        row.policy, row.queued = sum(acc["dropped_by_policy"].values()), acc["queued"]
        flow = ledger.across(acc, rx)
        row.on_link, row.lost, row.lost_seen = flow["sent"], flow["lost"], flow["lost_on_link"]
        exact = link.get("on_link")
        if isinstance(exact, dict) and "lost_on_link" in exact and not link.get("fragments_sent"):
            # Named by acks (wire-format 15.7), in copies: messages only where none went in
            # fragments (then the receiver's count of incomplete messages above stands). Never
            # more than were lost: a copy the acks name missing may still have arrived.
            row.lost_seen = min(int(exact["lost_on_link"]), row.lost)
        row.imbalances = ledger.imbalances(acc) + ledger.imbalances(rx)
        return row
    row.taken = out.get("taken", 0)
    row.policy = sum(int(link.get(r, 0)) for r in DROP_REASONS)
    row.queued = int(link.get("queued", 0))
    row.on_link = max(0, int(link.get("offered", 0)) - row.policy - row.queued)
    row.lost = max(0, row.on_link - inc.get("received", 0))
    return row


def build_report(out_dir: Path) -> Report:
    out_dir = Path(out_dir)
    op = list(read_records(out_dir / "operator.jsonl"))
    veh = list(read_records(out_dir / "vehicle.jsonl"))
    surface = _load_json(out_dir / "bridge_surface.json")
    vehicle = _load_json(out_dir / "bridge_vehicle.json")
    emulator = _load_json(out_dir / "emulator.json")

    def ev(records, name):
        return [r for r in records if r.get("ev") == name]

    rows = []
    cmd = _topic_row("/turtle1/cmd_vel", "surface → vehicle", surface, vehicle)
    cmd.published = len(ev(op, "cmd"))
    cmd.delivered = len(ev(veh, "cmd"))
    cmd.latencies = _latencies_by_key(((r["k"], r["t"]) for r in ev(op, "cmd")),
                                      ((r["k"], r["t"]) for r in ev(veh, "cmd")))
    rows.append(cmd)

    def pose_key(r):
        return tuple(round(r[k] / step) for k, step in POSE_KEY_STEPS)
    pose = _topic_row("/turtle1/pose", "vehicle → surface", vehicle, surface)
    pose.published = len(ev(veh, "pose"))
    pose.delivered = len(ev(op, "pose_rx"))
    pose.latencies = _latencies_by_key(((pose_key(r), r["t"]) for r in ev(veh, "pose")),
                                       ((pose_key(r), r["t"]) for r in ev(op, "pose_rx")))
    rows.append(pose)

    bat = _topic_row("/vehicle/battery", "vehicle → surface", vehicle, surface)
    bat.published = len(ev(veh, "battery"))
    bat.delivered = len(ev(op, "battery_rx"))
    bat.latencies = [r["t"] - r["stamp"] for r in ev(op, "battery_rx")]
    rows.append(bat)

    logrow = _topic_row("/vehicle/log", "vehicle → surface", vehicle, surface)
    logrow.published = len(ev(veh, "log"))
    logrow.delivered = len(ev(op, "log_rx"))
    logrow.latencies = _latencies_by_key(((r["seq"], r["t"]) for r in ev(veh, "log")),
                                         ((r["seq"], r["t"]) for r in ev(op, "log_rx")))
    rows.append(logrow)

    services = []
    for name in ("/vehicle/set_pen", "/turtle1/teleport_absolute"):
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


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x * 1000:.0f} ms"


COLUMNS = """\
  taken: by the sending bridge from its local graph; sub drop: messages the sending bridge's
  subscription lost before it took them (its ROS queue overflowed); on link: put on the wire;
  policy: dropped by the topic's link policy (superseded by a newer one, rate, ttl, overflow);
  lost (seen): put on the link, never received by the far bridge; (seen) of those, how many
  the link knows were lost: on wire format 2 those the far side's acknowledgements name
  missing (wire-format 15.7), for a fragmented topic those of which some fragments arrived"""


def format_report(report: Report) -> str:
    lines = []
    head = (f"{'topic':<20} {'direction':<18} {'published':>9} {'taken':>6} {'sub drop':>8} "
            f"{'on link':>7} {'policy':>6} {'lost (seen)':>11} {'delivered':>9} {'latency p50':>11} {'p95':>8}")
    lines += [head, "-" * len(head)]
    for r in report.topics:
        lost = f"{r.lost} ({r.lost_seen})" if r.lost_seen else str(r.lost)
        lines.append(f"{r.name:<20} {r.direction:<18} {r.published:>9} {r.taken:>6} {r.sub_dropped:>8} "
                     f"{r.on_link:>7} {r.policy:>6} {lost:>11} {r.delivered:>9} {_ms(r.p50):>11} {_ms(r.p95):>8}")
    for r in report.topics:
        for problem in r.imbalances:
            lines.append(f"  {r.name}: counters do not add up: {problem}")
    lines += COLUMNS.splitlines()
    lines.append("")
    shead = (f"{'service':<28} {'calls':>5} {'ok':>4} {'failed':>6} {'policy':>6} "
             f"{'lost on link':>12} {'round trip p50':>14} {'p95':>8}")
    lines += [shead, "-" * len(shead)]
    for s in report.services:
        lost = "-" if s.lost_on_link is None else str(s.lost_on_link)
        lines.append(f"{s.name:<28} {s.calls:>5} {s.ok:>4} {s.failed:>6} {s.policy:>6} {lost:>12} "
                     f"{_ms(median(s.rtts) if s.rtts else None):>14} {_ms(percentile(s.rtts, 95)):>8}")
    lines.append("  lost on link: requests and responses (copies included) the far side's "
                 "acknowledgements name missing; re-sent by the bridges (wire-format 15.6)")
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


def frame_sizes(manifest: Path, folders: list[Path]) -> list[FrameSize]:
    """Frame bytes of a representative /turtle1/cmd_vel and /turtle1/pose as `manifest`
    sends them, next to the same messages in profile native without field encodings
    (codecs built for the occasion, so the numbers follow the manifest). On wire format 2 (no
    rmw_desert entry) a frame is the message alone in a packet's envelope, sealed as the
    bridge seals packets when the topic is protected (one tag; a sync packet has 13 bytes
    more); on wire format 1 the payload sealed as its bridge seals it. Measured, under a
    throwaway key."""
    import tempfile

    from uwgen.bridge.plan import is_rmw_desert
    from uwgen.codegen import generate
    from uwgen.runtime.wire import envelope as env
    from uwgen.runtime.wire.framing import OVERHEAD
    from uwgen.security import packetwire, wire
    from uwgen.security.keys import new_epoch, new_master_key, working_key

    samples = {
        "/turtle1/cmd_vel": lambda cls: cls(linear=_vec(cls, 0.4), angular=_vec(cls, 0.0, z=0.3)),
        "/turtle1/pose": lambda cls: cls(x=5.54, y=7.12, theta=1.571, linear_velocity=0.4, angular_velocity=0.0),
    }
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        pkg = generate(Path(tmp), "uwgen_demo_sizes", folders=folders, manifest=manifest,
                       names=["geometry_msgs/msg/Twist", "turtlesim/msg/Pose"])
        plan = getattr(pkg.MANIFEST, "security", None)
        modes = dict(plan.modes) if plan is not None else {}
        v2 = not any(is_rmw_desert(e) for e in (*pkg.TOPICS.values(), *pkg.SERVICES.values()))
        aead = wire.new_aead(working_key(new_master_key(), "sizes", 1, new_epoch()))
        for topic in pkg.TOPICS.values():
            if topic.name not in samples:
                continue
            msg = samples[topic.name](topic.codec.plain_class())
            native = pkg.codec(topic.type_name, "native").encode(msg, [0, topic.id])
            encoded = any(c is topic.codec for c in getattr(pkg, "VARIANTS", {}).values())
            how = topic.profile + (" + field encodings" if encoded else "")
            payload = topic.encode(msg)
            mode = modes.get(topic.id, "off")
            fingerprint = bytes(getattr(topic, "fingerprint", b"") or b"")
            if v2:
                body = env.strip_packed_head(payload) if topic.profile == "packed" else payload
                alone = env.Envelope(1, 1, (env.from_v1(body),))
                plain = alone.encode()
                sent = plain if not modes else packetwire.seal(     # a secured link seals every packet
                    aead, alone, 1, lambda m: modes.get(m.id) == wire.ENCRYPT, lambda i: fingerprint)
                out.append(FrameSize(topic.name, OVERHEAD + env.HEAD + env.v1_message_size(native, True),
                                     len(sent) + OVERHEAD, how, mode, len(sent) - len(plain)))
                continue
            sent = payload
            if mode != "off":
                sent = wire.seal(aead, mode, 1, 1, payload, fingerprint)
            out.append(FrameSize(topic.name, len(native) + OVERHEAD, len(sent) + OVERHEAD, how, mode,
                                 len(sent) - len(payload)))
    return out


def _vec(twist_cls, x: float, z: float = 0.0):
    """A Vector3 of the plain Twist class's package (its default value's class)."""
    v = type(twist_cls().linear)()
    v.x, v.z = x, z
    return v


def plot_paths(report: Report, path: Path, title: str = "") -> Path:
    import matplotlib.pyplot as plt

    fig = path_figure(report, title)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def path_figure(report: Report, title: str = ""):
    """The figure of the commanded and reported paths (the caller saves and closes it)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 6.0), dpi=110)
    if report.commanded:
        xs, ys = zip(*report.commanded)
        ax.plot(xs, ys, "--", color="tab:blue", lw=2, label="commanded square (operator's waypoints)")
    if report.truth:
        xs, ys = zip(*report.truth)
        ax.plot(xs, ys, "-", color="0.6", lw=1, label="vehicle (simulator, local)")
    if report.reported:
        xs, ys = zip(*report.reported)
        ax.plot(xs, ys, "o", color="tab:orange", ms=3.5, label="reported (poses received at surface)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.3)
    # Below the axes, never over the square: the paths fill the plot.
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8, frameon=False)
    ax.set_title(title or "uwgen demo: commanded vs reported path", fontsize=10)
    fig.tight_layout()
    return fig
