"""The server side's book of action results: sent again until acknowledged, given up after 2
accept_timeouts, kept for a repeated goal (no rclpy: times are passed in)."""
from __future__ import annotations

from uwgen.bridge.action_results import RECENT_RESULTS, ResultBook
from uwgen.runtime.delivery.reliable import command_rtt

ACCEPT = 12.0          # accept_timeout: first RTO 3 s (a quarter), given up after 24 s


def book() -> ResultBook:
    return ResultBook(ACCEPT, command_rtt(ACCEPT, 0.2))


def test_a_result_goes_again_after_its_rto_until_acknowledged():
    b = book()
    b.sent(5, b"goal", b"result", arrived=0.0, now=1.0)
    assert list(b.due(3.9)) == []                   # RTO 3 s from 1.0
    assert list(b.due(4.0)) == [b"result"]
    assert b.acknowledged(5, now=5.0).payload == b"result"
    assert list(b.due(100.0)) == []                 # nothing waits any more
    assert b.acknowledged(5, now=6.0) is None       # a second acknowledgement is news to nobody


def test_a_result_never_acknowledged_is_given_up_after_two_accept_timeouts_once():
    b = book()
    b.sent(5, b"goal", b"result", arrived=0.0, now=0.0)
    sends = [p for t in range(1, 2 * int(ACCEPT)) for p in b.due(float(t))]
    assert sends and all(p == b"result" for p in sends)
    assert list(b.due(2 * ACCEPT)) == [None]        # counted once as results_unacked
    assert list(b.due(2 * ACCEPT + 10)) == []


def test_only_a_result_acknowledged_after_one_send_is_a_round_trip_sample():
    once, twice = book(), book()
    for b in (once, twice):
        b.sent(1, b"g", b"r", arrived=0.0, now=0.0)
    list(twice.due(3.0))                            # sent a second time: ambiguous (Karn)
    once.acknowledged(1, now=2.0)
    twice.acknowledged(1, now=3.5)
    assert once.rtt.samples == 1 and once.rtt.srtt == 2.0
    assert twice.rtt.samples == 0


def test_a_copy_of_a_finished_goal_gets_its_result_within_the_repeat_window_only():
    b = book()
    b.sent(7, b"goal", b"result", arrived=10.0, now=12.0)
    assert b.repeat_of(7, b"goal", now=20.0) == b"result"
    assert b.repeat_of(7, b"other goal", now=20.0) is None       # same handle, new goal
    assert b.repeat_of(8, b"goal", now=20.0) is None
    assert b.repeat_of(7, b"goal", now=10.0 + 1.5 * ACCEPT + 0.1) is None


def test_a_new_goal_on_a_handle_forgets_the_old_result():
    b = book()
    b.sent(7, b"goal", b"result", arrived=0.0, now=0.0)
    b.forget(7)
    assert b.result_of(7) is None and list(b.due(10.0)) == []


def test_a_cancelled_finished_goal_is_not_sent_again_but_its_result_is_kept():
    b = book()
    b.sent(7, b"goal", b"result", arrived=0.0, now=0.0)
    b.stop_sending(7)
    assert list(b.due(10.0)) == [] and b.result_of(7) == b"result"


def test_only_the_last_results_are_kept():
    b = book()
    for handle in range(RECENT_RESULTS + 3):
        b.sent(handle, b"g%d" % handle, b"r%d" % handle, arrived=0.0, now=0.0)
    assert b.result_of(0) is None and b.result_of(2) is None
    assert b.result_of(3) == b"r3" and b.result_of(RECENT_RESULTS + 2) == b"r%d" % (RECENT_RESULTS + 2)


def test_a_result_goes_again_when_its_copy_is_due_not_on_its_timer():
    b = book()
    b.sent(5, b"goal", b"result", arrived=0.0, now=0.0, turn=4)
    assert list(b.due(20.0, ready=lambda u: False)) == []      # never due: never sent
    assert list(b.due(1.0, ready=lambda u: u.turn == 4)) == [b"result"]   # before its RTO
