"""The emulator against real DESERT: every traced pattern, replayed write for write.

The traces (../shared/calibration, or $UWGEN_CALIBRATION_DIR) are measurements of a real
DESERT 4.0.0; `uwgen.emulator.calibration` replays their writes through the core. Every
pattern and direction found there, at whatever distance it was traced, must match:
delivered fraction within 5 percentage points, median latency within 10 %, and chunks
neither merged nor split where DESERT did not.
"""
from __future__ import annotations

import pytest

from uwgen.emulator import EmulatorCore, NodeSpec, Scenario, SnrModel
from uwgen.emulator import calibration as cal

TRACE_DIR = cal.find_trace_dir()
SEEDS = range(1, 33)      # the emulated side pooled over seeds: its own noise is small

needs_traces = pytest.mark.skipif(TRACE_DIR is None, reason="no calibration traces here "
                                  "(set UWGEN_CALIBRATION_DIR)")


@pytest.fixture(scope="module")
def rows():
    return cal.compare(cal.load_traces(TRACE_DIR), seeds=SEEDS)


def _ids(rows):
    return [f"{r.pattern}-{r.side}-{r.distance:.0f}m" for r in rows]


@needs_traces
def test_every_trace_has_writes_and_a_known_distance(rows):
    assert rows, f"no traces in {TRACE_DIR}"
    assert all(r.real.writes > 0 and r.distance > 0 for r in rows)


@needs_traces
def test_delivered_fraction_within_5_points_of_real_desert(rows):
    off = {f"{r.pattern} {r.side} {r.distance:.0f} m": (round(r.real.fraction, 3),
                                                       round(r.emulated.fraction, 3))
           for r in rows if abs(r.emulated.fraction - r.real.fraction) > 0.05}
    assert not off, f"(real, emulated) delivered fraction off by more than 5 points: {off}"


@needs_traces
def test_median_latency_within_10_percent_of_real_desert(rows):
    off = {f"{r.pattern} {r.side} {r.distance:.0f} m": (round(r.real.median_latency, 3),
                                                       round(r.emulated.median_latency, 3))
           for r in rows if r.real.latencies
           and abs(r.emulated.median_latency / r.real.median_latency - 1) > 0.10}
    assert not off, f"(real, emulated) median latency off by more than 10 %: {off}"


@needs_traces
def test_chunks_are_whole_writes_as_in_real_desert(rows):
    for r in rows:
        assert r.emulated.merged == r.real.merged == 0, r.pattern
        assert r.emulated.delivered > 0 or r.real.delivered == 0, r.pattern


@needs_traces
def test_the_replay_cuts_where_desert_crashed():
    crashed = [t for t in cal.load_traces(TRACE_DIR) if t.crashed]
    for tr in crashed:
        emu = cal.replay(tr)
        late = [w for w in tr.writes if w[0] > tr.end]
        assert sum(d.delivered for d in emu.values()) <= len(tr.writes) - len(late)


# --- the two model changes the traces led to, shown without the traces -------------------

def test_a_packet_that_arrived_while_sending_is_not_carrier_for_the_mac():
    # a (period 0.1 s, 64 B = 0.113 s on the air) sends back to back: 0.11, 0.233, 0.357,
    # then its 4th packet. b's one packet, sent at 0.26, reaches a at 0.46..0.573, while a
    # sends its 3rd (0.357..0.470): a's PHY never acquires it, so a's MAC does not hear it
    # and sends its 4th one listen after its 3rd ends (0.48), not after b's packet (0.583).
    scen = Scenario(nodes=[NodeSpec("a", dest="b", period=0.1),
                           NodeSpec("b", position=(300, 0, 0), dest="a", phase=0.05)],
                    period=0.2, bitrate=4800.0, listen_jitter=0.0)
    core = EmulatorCore(scen)
    for n in ("a", "b"):
        core.client_attached(n, 0.0)
    core.client_data("a", 0.0, bytes(64 * 4))
    core.client_data("b", 0.0, bytes(64))
    out = core.run_until_idle()
    a_sends = sorted(d.sent_at for d in out if d.source == "a")
    assert a_sends[-1] == pytest.approx(0.47 + 0.01, abs=1e-3)
    assert core.counters("a")["lost_collision"] == 1        # b's packet, unheard


def test_interference_counts_only_for_the_share_of_the_reception_it_overlaps():
    # MEANPOWER: c's packet, as strong as a's at b, overlapping 5 % of it costs little;
    # overlapping all of it kills it.
    def lost_at_b(c_delay: float) -> int:
        snr = SnrModel(tx_power_db=150.0, spreading=1.75, threshold_db=5.0, fading_db=0.0)
        scen = Scenario(nodes=[NodeSpec("a", dest="b"),
                               NodeSpec("b", position=(300, 0, 0), dest="a"),
                               NodeSpec("c", position=(600, 0, 0), dest="b", phase=c_delay)],
                        period=1.0, bitrate=4800.0, listen_jitter=0.0, snr=snr)
        core = EmulatorCore(scen)
        core.client_attached("b", 0.0)
        core.client_data("a", 0.0, bytes(64))
        core.client_data("c", 0.0, bytes(64))
        core.run_until_idle()
        return core.counters("b")["lost_collision"]

    air = 68 * 8 / 4800
    # c is 300 m from b like a; its packet starts (air - 0.005) s after a's at b: it is the
    # one b is not locked on (lost), and a's survives the small overlap.
    assert lost_at_b(air - 0.005) == 1
    # c's packet starting at the same instant as a's: both lost.
    assert lost_at_b(0.0) == 2
