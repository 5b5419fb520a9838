"""The dispatcher: one header read per payload, routed by (kind, id); everything that fits
no route is counted under the reason it does not fit."""
from __future__ import annotations

import pytest

from uwgen.bridge.counters import BridgeCounters
from uwgen.bridge.dispatch import Dispatcher
from uwgen.runtime.wire.codec import pack_items


@pytest.fixture
def dispatcher():
    d = Dispatcher(BridgeCounters())
    d.got = []
    d.route(0, 5, lambda ident, payload: d.got.append(("topic", ident, payload)))
    d.route(3, 20, lambda ident, payload: d.got.append(("response", ident, payload)))
    d.sends(2, 20)      # this side calls service 20
    d.sends(0, 7)       # and publishes topic 7
    return d


def test_routes_by_kind_and_id(dispatcher):
    for payload in (pack_items([0, 5, 1.5]), pack_items([3, 20, 9, "ok"])):
        dispatcher.dispatch(payload)
    assert [(kind, ident) for kind, ident, _ in dispatcher.got] == [("topic", 5), ("response", 20)]
    assert dispatcher.got[0][2] == pack_items([0, 5, 1.5])     # the whole payload, untouched


@pytest.mark.parametrize("payload, counter", [
    (b"", "bad_header"),
    (b"\x01\x05", "bad_header"),                       # kind 1 is never valid
    (pack_items([0, 7, "x"]), "wrong_direction"),      # our own topic came back
    (pack_items([2, 20, 1]), "wrong_direction"),       # our own request came back
    (pack_items([2, 5, 1]), "bad_kind"),               # a topic id as a request
    (pack_items([0, 20, 1]), "bad_kind"),              # a service id as a topic
    (pack_items([0, 99, 1]), "unknown_id"),
])
def test_what_fits_no_route_is_counted(dispatcher, payload, counter):
    dispatcher.dispatch(payload)
    counts = vars(dispatcher.counters)
    assert counts[counter] == 1 and sum(counts.values()) == 1
    assert dispatcher.got == []


def test_a_route_cannot_be_taken_twice(dispatcher):
    with pytest.raises(ValueError, match="kind 0 id 5 is routed twice"):
        dispatcher.route(0, 5, lambda ident, payload: None)
