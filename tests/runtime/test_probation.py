"""Probation (sans-IO): when a fresh connection counts as connected, and when it looks unserved."""
from __future__ import annotations

import pytest

from uwgen.runtime.link.probation import Event, Probation, reconnect_cap


def test_a_connection_is_proven_after_the_probation_and_only_once():
    p = Probation(probation=0.3, unserved_after=10)
    p.opened(100.0)
    assert p.tick(100.29) is None and not p.proven
    assert p.tick(100.3) is Event.PROVEN and p.proven
    assert p.tick(100.4) is None


def test_data_proves_a_connection_at_once():
    p = Probation(probation=0.3, unserved_after=10)
    p.opened(0.0)
    assert p.received(0.01) is Event.PROVEN
    assert p.received(0.02) is None and p.tick(0.5) is None


def test_unserved_is_suspected_once_only_when_we_wrote_and_nothing_ever_arrived():
    p = Probation(probation=0.3, unserved_after=10)
    p.opened(0.0)
    p.tick(0.3)
    assert p.tick(20.0) is None                 # we never wrote: nothing to say
    p.wrote()
    assert p.tick(20.0) is Event.UNSERVED
    assert p.tick(40.0) is None                 # once per connection
    p.opened(50.0)                              # a new connection starts over
    p.tick(50.3), p.wrote()
    p.received(55.0)
    assert p.tick(70.0) is None                 # data came: served


def test_deadline_says_when_to_look_again():
    p = Probation(probation=0.3, unserved_after=10)
    p.opened(5.0)
    assert p.deadline() == pytest.approx(5.3)
    p.tick(5.3)
    assert p.deadline() == pytest.approx(15.0)
    p.received(6.0)
    assert p.deadline() is None


@pytest.mark.parametrize("period, cap", [(0.2, 1.0), (1.0, 1.0), (2.5, 2.5)])
def test_reconnect_cap_is_one_period_or_one_second_whichever_is_larger(period, cap):
    assert reconnect_cap(period) == cap
