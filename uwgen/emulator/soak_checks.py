"""The soak's books (uwgen/emulator/soak.py `Soak.check`): what must add up after a run.

Per flow: nothing delivered twice or out of order, no false frame beyond what is allowed,
sent = delivered + lost with the link's own ledger (wire-format.md section 15.7) closing; per
side: every channel's offered = sent + queued + dropped and every byte written read by DESERT;
drained: every packet DESERT took delivered, lost or dropped by a restart.
"""
from __future__ import annotations

from uwgen.emulator.core import LOSS_CAUSES
from uwgen.runtime.link.scheduler import DROP_REASONS

SIDES = ("surface", "vehicle")


def problems(soak, drained: bool = False, corrupt_allowed: int = 0) -> list[str]:
    """What does not add up in `soak` (a `Soak`), each as one sentence: see `Soak.check`."""
    found = []
    for name, rec in soak.received.items():
        if rec.repeated:
            found.append(f"{name}: {rec.repeated} messages delivered twice or out of order")
    if soak.corrupt() > corrupt_allowed:
        found.append(f"{soak.corrupt()} messages delivered with wrong content "
                        f"(allowed {corrupt_allowed})")
    if soak.unknown:
        found.append(f"{soak.unknown} payloads of no flow delivered")
    for side, s in soak.sides.items():
        for key, c in s.link.scheduler.stats().items():
            accounted = c["sent"] + c["queued"] + sum(c[r] for r in DROP_REASONS)
            if c["offered"] != accounted:
                found.append(f"{side} channel {key}: offered {c['offered']} != sent + "
                                f"queued + dropped {accounted}")
        wrote = s.link.connection.outbox.stats.bytes_sent
        if wrote != soak.core.counters(side)["bytes_in"]:
            found.append(f"{side}: the link wrote {wrote} bytes, DESERT read "
                            f"{soak.core.counters(side)['bytes_in']}")
    for name, row in soak.ledger().items():
        # sent = delivered + lost: nothing arrives that was not sent, the receiver never
        # counts more lost than did not arrive, and the sender's own ledger (wire-format 15.7),
        # once there, says exactly what arrived and what did not.
        if row["lost"] < 0:
            found.append(f"{name}: delivered {row['delivered']} > sent {row['sent']}")
        if drained and row["lost_seen"] > row["lost"]:
            found.append(f"{name}: the receiver saw {row['lost_seen']} lost, but only "
                            f"{row['lost']} of {row['sent']} sent did not arrive")
        link = row["link"]
        if link is not None and link["sent"] != (link["delivered"] + link["lost_on_link"]
                                                 + link.get("in_flight", 0)
                                                 + link.get("unacknowledged", 0)
                                                 + link.get("unknown", 0)):
            found.append(f"{name}: the link's ledger does not close: {link}")
        flow = next(f for f in soak.flows if f.name == name)
        whole = max(flow.sizes) <= soak.sides[flow.src].link.fragmenter.max_payload
        flying = link.get("in_flight", 0) if link is not None else 0
        if drained and whole and link is not None and not (
                link["sent"] == row["sent"]
                and link["delivered"] <= row["delivered"] <= link["delivered"] + flying
                and link["lost_on_link"] + link.get("unacknowledged", 0) <= row["lost"]
                <= link["lost_on_link"] + link.get("unacknowledged", 0) + flying):
            # unfragmented, never re-sent: the link's copies are the flow's messages; exact
            # but for copies no acknowledgement named yet (in_flight: the tail of a run)
            found.append(f"{name}: the link's ledger says sent {link['sent']} delivered "
                            f"{link['delivered']} lost {link['lost_on_link']} (+ "
                            f"{link.get('unacknowledged', 0)} unacknowledged, {flying} in "
                            f"flight); sent {row['sent']} = "
                            f"delivered {row['delivered']} + lost {row['lost']}")
    if drained:
        for src in SIDES:
            dst = next(other for other in SIDES if other != src)
            a, b = soak.core.counters(src), soak.core.counters(dst)
            lost = sum(b[f"lost_{c}"] for c in LOSS_CAUSES)
            if a["packets_queued"] != b["packets_delivered"] + lost + a["dropped_restart"]:
                found.append(
                    f"{src}->{dst}: {a['packets_queued']} packets != delivered "
                    f"{b['packets_delivered']} + lost {lost} + dropped at restarts "
                    f"{a['dropped_restart']}")
    return found
