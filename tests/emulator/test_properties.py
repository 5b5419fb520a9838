"""Properties of the core for any sequence of client writes (hypothesis)."""
from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.emulator import EmulatorCore

from .helpers import two_nodes

writes = st.lists(st.tuples(st.floats(min_value=0.0, max_value=5.0, allow_nan=False),
                            st.binary(min_size=1, max_size=300)), min_size=1, max_size=25)


@settings(max_examples=60, deadline=None)
@given(writes=writes, mrl=st.integers(min_value=1, max_value=100),
       distance=st.floats(min_value=1.0, max_value=3000.0))
def test_one_way_traffic_arrives_whole_in_order_cut_at_max_read_length(writes, mrl, distance):
    scen = two_nodes(distance, period=0.1, bitrate=100_000.0, max_read_length=mrl,
                     listen_jitter=0.01)
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    stream = b""
    for t, data in sorted(writes, key=lambda w: w[0]):
        core.client_data("a", t, data)
        stream += data
    out = core.run_until_idle()
    assert b"".join(d.data for d in out) == stream
    assert all(1 <= len(d.data) <= mrl for d in out)
    sends = [d.sent_at for d in out]
    # one per period (each send follows its tick by a 10-20 ms listen)
    assert all(b - a >= 0.1 - 0.01 - 1e-9 for a, b in zip(sends, sends[1:]))
    assert all(d.time > d.sent_at > d.queued_at for d in out)
    assert core.counters("a")["queue_bytes"] == 0


@settings(max_examples=40, deadline=None)
@given(writes=writes, per=st.floats(min_value=0.0, max_value=1.0), seed=st.integers(0, 1000))
def test_with_losses_what_arrives_is_an_in_order_subsequence_and_every_packet_is_counted(
        writes, per, seed):
    scen = two_nodes(500.0, period=0.1, bitrate=100_000.0, max_read_length=16, per=per,
                     seed=seed)
    core = EmulatorCore(scen)
    core.client_attached("b", 0.0)
    for t, data in sorted(writes, key=lambda w: w[0]):
        core.client_data("a", t, data)
    out = core.run_until_idle()
    offsets = [d.offset for d in out]
    assert offsets == sorted(set(offsets))
    a, b = core.counters("a"), core.counters("b")
    assert a["packets_queued"] == a["packets_sent"]
    assert b["packets_delivered"] + b["lost_per"] == a["packets_sent"]
    assert b["packets_delivered"] == len(out)
