"""PNG plots of recordings (`uwgen log --plot`): four panels over the run's time.

- delivery: the share of each side's packets the other side read, per BIN seconds
  (both sides' recordings needed);
- latency: each matched message, publication to delivery, per topic;
- air use: bytes each side put on the water per second (DESERT's header included);
- losses by cause: messages dropped by link policy (superseded, expired, ...), packets
  lost on the way, packets dropped on receive (security, copies, bad envelopes).
"""
from __future__ import annotations

from collections import Counter
from pathlib import Path

from uwgen import pngplot
from uwgen.fieldkit.summary import Summary

BIN = 10.0   # s per bar of the delivery and air-use panels


def _bins(points: list[tuple[float, float]], t0: float, width: float) -> dict[float, float]:
    out: Counter = Counter()
    for t, v in points:
        out[t0 + (t - t0) // width * width] += v
    return dict(sorted(out.items()))


def plot_summary(s: Summary, path: Path, title: str = "") -> Path:
    plt = pngplot.pyplot()

    spans = [r.span for r in s.recordings if r.span]
    t0 = min(a for a, _ in spans) if spans else 0.0
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), dpi=100)
    (ax_del, ax_lat), (ax_air, ax_loss) = axes

    for name, side in sorted(s.sides.items()):
        known = [(t, a) for t, _b, a in side.sent if a is not None]
        if known:
            sent = _bins([(t, 1) for t, _ in known], t0, BIN)
            arrived = _bins([(t, int(a)) for t, a in known], t0, BIN)
            xs = [t - t0 for t in sent]
            ax_del.plot(xs, [arrived.get(t, 0) / n for t, n in sent.items()], "o-", ms=3,
                        label=f"{name}'s packets")
        air = _bins([(t, b) for t, b, _a in side.sent], t0, BIN)
        ax_air.step([t - t0 for t in air], [b / BIN for b in air.values()], where="post",
                    label=f"{name} ({side.air_bytes} B)")
    ax_del.set_ylim(-0.05, 1.05)
    ax_del.set_title(f"delivery: share of packets read by the far side ({BIN:g} s bins)", fontsize=9)
    ax_air.set_title(f"air use per side (B/s over {BIN:g} s)", fontsize=9)
    if not s.both:
        ax_del.text(0.5, 0.5, "needs both sides' recordings", ha="center", transform=ax_del.transAxes)

    for name, pts in sorted(s.latency_series.items()):
        if pts:
            ax_lat.plot([t - t0 for t, _ in pts], [lat for _, lat in pts], ".", ms=3, label=name)
    ax_lat.set_title("latency: publication to delivery (s)", fontsize=9)

    causes: Counter = Counter()
    for side, drops in s.policy.items():
        for reason, n in drops.items():
            if n:
                causes[f"{side}: {reason} (policy, msgs)"] += n
    for name, side in s.sides.items():
        if side.lost:
            causes[f"{name}: lost on the way (packets)"] += side.lost
        for reason, n in side.dropped.items():
            causes[f"{name} received: {reason} (packets)"] += n
    if causes:
        labels, values = zip(*sorted(causes.items()))
        ax_loss.barh(range(len(values)), values, color="tab:red")
        ax_loss.set_yticks(range(len(values)), labels, fontsize=7)
    else:
        ax_loss.text(0.5, 0.5, "no losses", ha="center", transform=ax_loss.transAxes)
    ax_loss.set_title("losses by cause", fontsize=9)

    for ax in (ax_del, ax_lat, ax_air):
        ax.set_xlabel("s since the recording began", fontsize=8)
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.suptitle(title or f"uwgen log: {', '.join(f'{r.network}/{r.side}' for r in s.recordings)}",
                 fontsize=10)
    fig.tight_layout()
    return pngplot.save(fig, path)
