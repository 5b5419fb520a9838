"""The per-topic books of a bridge (uwgen.runtime.delivery.ledger): identities, and the subscription's QoS."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from uwgen.runtime.delivery import ledger
from uwgen.bridge.counters import TopicCounters
from uwgen.manifest.model import LinkPolicy, Qos


def test_outgoing_books_balance_when_every_message_is_accounted_for():
    c = TopicCounters(taken=20, encode_errors=1)
    channel = {"offered": 17, "sent": 10, "superseded": 3, "overflow": 2, "expired": 1, "queued": 1}
    acc = ledger.outgoing(c, channel, subscription_lost=4, echo_dropped=2)
    assert acc["published"] == 24 and acc["dropped_by_policy"]["echo_guard"] == 2
    assert ledger.imbalances(acc) == []
    acc["queued"] = 0                      # one message unaccounted for
    assert ledger.imbalances(acc) == ["taken 20 != sent 10 + dropped by policy 9 + queued 0"]


def test_incoming_books_and_the_flow_across_sides():
    rx = ledger.incoming(TopicCounters(received=7, decode_errors=1, published=6), lost_on_link=2)
    assert ledger.imbalances(rx) == []
    flow = ledger.across({"sent": 10}, rx)
    assert flow == {"sent": 10, "received": 7, "lost": 3, "lost_on_link": 2, "unseen_loss": 1}


def test_lost_on_link_reads_json_keys_back_as_ids():
    assert ledger.lost_on_link({"fragments": {"lost_by_id": {"7": 2}}}) == {7: 2}
    assert ledger.lost_on_link({"fragments": None}) == {}


def test_a_fifo_topic_subscription_holds_what_the_link_queue_can():
    fifo = SimpleNamespace(qos=Qos(depth=10), policy=LinkPolicy(queue="fifo", depth=50))
    latest = SimpleNamespace(qos=Qos(depth=10), policy=LinkPolicy(queue="latest"))
    assert ledger.subscription_qos(fifo) == Qos(depth=50)
    assert ledger.subscription_qos(latest) == Qos(depth=10)
    deep = SimpleNamespace(qos=Qos(depth=100), policy=LinkPolicy(queue="fifo", depth=50))
    assert ledger.subscription_qos(deep).depth == 100


def test_message_lost_events_are_counted_per_topic():
    losses = ledger.SubscriptionLosses()
    cb = losses.callbacks(7)
    cb.message_lost(SimpleNamespace(total_count=3, total_count_change=3))
    cb.message_lost(SimpleNamespace(total_count=5, total_count_change=2))
    assert losses.lost == {7: 5}


def test_final_summary_states_the_books_per_topic():
    from uwgen.bridge.main import _summary
    out = ledger.outgoing(TopicCounters(taken=9), {"sent": 5, "superseded": 4}, 1, 0)
    inc = ledger.incoming(TopicCounters(received=3, published=3), lost_on_link=1)
    text = _summary({"topics": {"/cmd": {"direction": "out", "taken": 9, "accounting": out},
                                "/log": {"direction": "in", "received": 3, "published": 3,
                                         "accounting": inc}}})
    assert text == ("/cmd published 10 taken 9 sent 5 dropped 4 queued 0; "
                    "/log received 3 lost on link 1 delivered 3")


# -- publication time (docs/seams.md section 4: ttl runs from publication) -----------------

def test_publication_time_comes_from_the_source_timestamp():
    from uwgen.bridge.topics import publication_time
    info = {"source_timestamp": 1_700_000_000_250_000_000, "received_timestamp": 0}
    assert publication_time(info, now=50.0, wall=1_700_000_002.0) == pytest.approx(48.25)


@pytest.mark.parametrize("info", [None, {}, {"source_timestamp": 0},
                                  {"source_timestamp": 1_700_000_009_000_000_000},   # ahead
                                  {"source_timestamp": 1_600_000_000_000_000_000}],  # ages ago
                         ids=["none", "empty", "zero", "future", "other clock"])
def test_an_untrustworthy_source_timestamp_means_now(info):
    from uwgen.bridge.topics import publication_time
    assert publication_time(info, now=50.0, wall=1_700_000_002.0) is None
