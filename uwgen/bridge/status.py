"""The bridge's ~/status: one JSON snapshot of everything counted, published on a timer,
optionally written to a stats file, with one log line per entry whose drops increased.

The parts count; this module only lays their sections out, publishes and reports.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

from uwgen.bridge.counters import DropReporter
from uwgen.bridge.wiring import Wiring


# Drop lines: at most one per entry (topic, service, action, the bridge's own) per this many
# seconds, however fast drops happen (docs/link-robustness.md, "Log volume").
REPORT_EVERY = 60.0


def _drop_sections(status: dict):
    """(label, [(section, name, counts), ...]) of every entry whose drops are reported."""
    for name, entry in status["topics"].items():
        yield name, [("topic", name, entry), ("link", name, entry.get("link", {}))]
    for name, entry in status["services"].items():
        yield name, [("service", name, {**entry, **entry.get("calls", {})}),
                     ("link", name, entry.get("link", {}))]
    for name, entry in status.get("actions", {}).items():
        yield name, [("action", name, entry), ("link", name, entry.get("link", {}))]
    yield "payloads", [("bridge", "", status["bridge"])]


class StatusReporter:
    def __init__(self, wiring: Wiring, network: str, side: str):
        self.w = wiring
        self.network, self.side = network, side
        self._drops = DropReporter()
        self._quiet_until: dict[str, float] = {}    # entry -> no drop line before this time
        self._pub = wiring.node.create_publisher(string_class(), "~/status", 10)

    def snapshot(self, link_stats: Any, **sections: Any) -> dict:
        """The status dict: identity, the DESERT settings, then the parts' `sections`
        (topics, services, discovery, bridge, ...) and the link's own stats, last."""
        opts = self.w.options
        return {"network": self.network, "side": self.side, "time": time.time(),
                "desert": {"host": opts.host, "port": opts.port,
                           "max_read_length": opts.link.max_read_length,
                           "period": opts.link.period},
                **sections, "link": link_stats}

    def publish(self, status: dict) -> dict:
        self._report_drops(status)
        msg = string_class()()
        msg.data = json.dumps(status, sort_keys=True, default=str)
        try:
            self._pub.publish(msg)
        except Exception:
            pass
        self.write(msg.data)
        return status

    def _report_drops(self, status: dict) -> None:
        """One line per entry whose drops increased, at most one per entry per REPORT_EVERY
        seconds whatever the input rate: the first at once, then the sum of the quiet time."""
        log, now = self.w.log, self.w.clock.now()
        for name, entry in status["topics"].items():
            if entry.get("link", {}).get("superseded") and f"sup{name}" not in self.w.said:
                self.w.said.add(f"sup{name}")
                log.info(f"{name}: published faster than its link policy sends; older "
                         "messages are superseded by newer ones (counted in ~/status)")
        for label, sections in _drop_sections(status):
            if now < self._quiet_until.get(label, float("-inf")):
                continue      # still counted: the next line after the quiet time has it
            parts = [part for section in sections for part in self._drops.changes(*section)]
            if parts:
                log.warning(f"{label}: dropped since last report: {', '.join(parts)}")
                self._quiet_until[label] = now + REPORT_EVERY

    def final_report(self, status: dict) -> None:
        """At shutdown: one line with every drop not yet reported (nothing if none)."""
        parts = []
        for label, sections in _drop_sections(status):
            changes = [part for section in sections for part in self._drops.changes(*section)]
            if changes:
                parts.append(f"{label} {', '.join(changes)}")
        if parts:
            self.w.log.warning(f"at shutdown, dropped since the last report: {'; '.join(parts)}")

    def write(self, text: str) -> None:
        """Replace the stats file (if any) with `text`, atomically."""
        path = self.w.options.stats_file
        if path is None:
            return
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(text)
            os.replace(tmp, path)
        except OSError as exc:
            self.w.say_once("statsfile", f"cannot write stats file {path}: {exc}")


def link_stats_of(link: Any) -> Any:
    try:
        return link.stats()
    except Exception as exc:
        return {"error": str(exc)}


def channel_stats(link_stats: Any) -> dict[int, dict]:
    """Per-channel counters from link.stats(), keyed by int id, whatever the key type."""
    if not isinstance(link_stats, dict):
        return {}
    chans = link_stats.get("channels", {})
    out: dict[int, dict] = {}
    if isinstance(chans, dict):
        for key, value in chans.items():
            try:
                out[int(key)] = value
            except (TypeError, ValueError):
                continue
    return out


def string_class() -> Any:
    from std_msgs.msg import String
    return String
