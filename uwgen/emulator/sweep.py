"""Packet delivery ratio against distance, simulated with the core (no sockets).

This is the emulator's counterpart of the rmw_desert thesis' chapter 7 figures (PDR of
one-way traffic against node distance, for wind 0, 5 and 10 m/s), and the check that
the SNR model's calibration (docs/emulator.md) still gives their shape.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from uwgen import pngplot
from uwgen.emulator.core import EmulatorCore
from uwgen.emulator.physics import SnrModel
from uwgen.emulator.scenario import NodeSpec, Scenario

DEFAULT_WINDS = (0.0, 5.0, 10.0)
DEFAULT_DISTANCES = tuple(250.0 * i for i in range(2, 41))   # 0.5 km .. 10 km


@dataclass(frozen=True)
class SweepPoint:
    wind: float
    distance: float     # metres
    sent: int
    delivered: int

    @property
    def pdr(self) -> float:
        return self.delivered / self.sent if self.sent else 0.0


def pdr_at(distance: float, snr: SnrModel, packets: int = 200, payload: int = 64,
           seed: int = 1, period: float = 0.2, bitrate: float = 4800.0) -> SweepPoint:
    """One-way traffic of `packets` packets of `payload` bytes over `distance` metres."""
    scen = Scenario(nodes=[NodeSpec("tx", position=(0.0, 0.0, 0.0), dest="rx"),
                           NodeSpec("rx", position=(distance, 0.0, 0.0), dest="tx")],
                    period=period, max_read_length=payload, bitrate=bitrate, snr=snr,
                    seed=seed)
    core = EmulatorCore(scen)
    core.client_attached("rx", 0.0)
    core.client_data("tx", 0.0, bytes(payload * packets))
    core.run_until_idle()
    c = core.counters("tx")
    return SweepPoint(snr.wind, distance, c["packets_sent"],
                      core.counters("rx")["packets_delivered"])


def pdr_sweep(winds=DEFAULT_WINDS, distances=DEFAULT_DISTANCES, packets: int = 200,
              seed: int = 1, base: SnrModel | None = None, payload: int = 64
              ) -> dict[float, list[SweepPoint]]:
    """PDR against distance for each wind speed (everything else from `base`)."""
    base = base or SnrModel()
    out: dict[float, list[SweepPoint]] = {}
    for w in winds:
        model = replace(base, wind=float(w))
        out[float(w)] = [pdr_at(d, model, packets=packets, payload=payload, seed=seed + i)
                         for i, d in enumerate(distances)]
    return out


def full_delivery_range(points: list[SweepPoint], at_least: float = 0.99) -> float:
    """The largest distance up to which every point delivered at least `at_least`."""
    best = 0.0
    for p in sorted(points, key=lambda p: p.distance):
        if p.pdr < at_least:
            break
        best = p.distance
    return best


def zero_delivery_distance(points: list[SweepPoint], at_most: float = 0.01) -> float | None:
    """The smallest distance from which on every point delivered at most `at_most`."""
    ordered = sorted(points, key=lambda p: p.distance)
    result = None
    for p in reversed(ordered):
        if p.pdr > at_most:
            break
        result = p.distance
    return result


def format_table(sweep: dict[float, list[SweepPoint]]) -> str:
    """A plain-text table: one row per distance, one PDR column per wind speed."""
    winds = list(sweep)
    header = "distance_km " + " ".join(f"wind_{w:g}".rjust(9) for w in winds)
    lines = [header]
    distances = [p.distance for p in sweep[winds[0]]]
    for i, d in enumerate(distances):
        cells = " ".join(f"{sweep[w][i].pdr:9.3f}" for w in winds)
        lines.append(f"{d / 1000:11.2f} {cells}")
    lines.append("")
    for w in winds:
        z = zero_delivery_distance(sweep[w])
        lines.append(f"wind {w:g} m/s: full delivery (>= 99 %) up to "
                     f"{full_delivery_range(sweep[w]) / 1000:.2f} km, nothing (<= 1 %) from "
                     + (f"{z / 1000:.2f} km" if z is not None else "beyond the sweep"))
    return "\n".join(lines)


def plot(sweep: dict[float, list[SweepPoint]], path: Path | str) -> Path:
    """Save the sweep as a PNG (matplotlib, Agg backend: no display needed)."""
    plt = pngplot.pyplot()

    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=110)
    for w, points in sweep.items():
        ax.plot([p.distance / 1000 for p in points], [p.pdr for p in points],
                marker="o", markersize=3, label=f"wind {w:g} m/s")
    ax.set_xlabel("distance between nodes (km)")
    ax.set_ylabel("packet delivery ratio")
    ax.set_ylim(-0.03, 1.03)
    ax.grid(True, alpha=0.3)
    ax.set_title("Emulated UW/PHYSICAL: 25 kHz, 5 kHz band, one-way traffic")
    ax.legend()
    fig.tight_layout()
    return pngplot.save(fig, path)
