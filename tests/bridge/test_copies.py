"""When a command goes again (uwgen.bridge.copies; docs/wire-format.md sections 5, 13, 15.6):
by the link under a MAC, by the bridge's timer without one, and never once its answer came."""
from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import pytest

from uwgen.bridge.copies import ANSWERED, QUEUED, SENT, Copies, answered_by
from uwgen.bridge.plan import BridgePlan
from uwgen.bridge.reliability import reliability_for, reliable_commands
from uwgen.manifest.model import LinkConfig, LinkPolicy
from uwgen.runtime.clock import ManualClock
from uwgen.runtime.delivery.reliable import command_rtt
from uwgen.runtime.link.scheduler import LinkScheduler

GENERATED = Path(__file__).resolve().parents[2] / "generated"
REQUEST = bytes.fromhex("02141982ce00")          # /echo id 20, seq 33486
RESPONSE = bytes.fromhex("03141982ce07")


def link_and_copies(link_resends: bool = False) -> tuple[LinkScheduler, Copies]:
    link = LinkScheduler(ManualClock())
    for key in (9, 20, 30):
        link.add_channel(key, LinkPolicy(queue="fifo", depth=8))
    return link, Copies(lambda key, payload: link.offer(key, payload), link.withdraw,
                        link_resends=link_resends)


def test_each_command_names_the_head_of_what_answers_it():
    assert answered_by(REQUEST) == bytes.fromhex("03141982ce")            # the response's seq
    assert answered_by(bytes.fromhex("02090705")) == bytes.fromhex("030907")  # goal: answer/result
    assert answered_by(bytes.fromhex("0309070405")) == bytes.fromhex("0209181f00")  # result: status
    assert answered_by(bytes.fromhex("02181e0700")) == bytes.fromhex("03181e07")  # id 30: 2 bytes
    assert answered_by(bytes.fromhex("0005")) is None and answered_by(b"") is None


def test_a_queued_copy_is_taken_back_when_its_answer_arrives_and_never_sent_after():
    link, copies = link_and_copies()
    assert copies.send(20, REQUEST) == SENT
    copies.heard(RESPONSE)                          # the link's thread, before it writes again
    assert link.next_payload(0.0) is None and link.stats()[20]["withdrawn"] == 1
    assert copies.send(20, REQUEST) == ANSWERED     # the executor has not handled it yet
    assert link.next_payload(1.0) is None


def test_an_answer_to_another_seq_takes_nothing_back():
    link, copies = link_and_copies()
    copies.send(20, REQUEST)
    copies.heard(bytes.fromhex("03141982cf07"))     # seq 33487
    assert link.next_payload(0.0) == (20, REQUEST)


def test_a_copy_whose_earlier_one_still_waits_in_the_queue_adds_nothing():
    link, copies = link_and_copies()
    link.offer(20, REQUEST)                         # the first, not yet sent
    assert copies.send(20, REQUEST) == QUEUED
    assert link.next_payload(0.0) == (20, REQUEST) and link.next_payload(1.0) is None


def test_a_result_copy_is_taken_back_by_its_result_status_only():
    link, copies = link_and_copies()
    result = bytes.fromhex("0309070406000101020305")
    copies.send(9, result)
    copies.heard(bytes.fromhex("0209181f01"))       # "result wanted": it did not arrive
    assert link.stats()[9]["withdrawn"] == 0
    copies.heard(bytes.fromhex("0209181f00"))       # "result received"
    assert link.next_payload(0.0) is None


def test_without_a_mac_a_copy_is_due_after_the_retransmission_timeout():
    _, copies = link_and_copies(link_resends=False)
    rtt = command_rtt(12.0, 0.2)
    assert copies.due(100.0, rtt).time == pytest.approx(103.0)      # a quarter of 12 s


def test_when_the_link_sends_commands_again_the_bridge_copies_only_past_their_deadline():
    _, copies = link_and_copies(link_resends=True)
    rtt = command_rtt(12.0, 0.2)
    due = copies.due(100.0, rtt)
    assert not copies.is_due(due, 111.9) and copies.is_due(due, 112.0)


@pytest.fixture(scope="module")
def demo():
    sys.path.insert(0, str(GENERATED))
    try:
        import uwgen_demo
        yield uwgen_demo
    finally:
        sys.path.remove(str(GENERATED))


def test_under_a_mac_the_link_numbers_and_sends_again_every_service_and_action(demo):
    plan = BridgePlan.from_package(demo, "surface")
    assert plan.mac.mode == "turns"
    commands = reliable_commands(plan)
    assert commands == {s.id: s.timeout for s in plan.services} | {
        a.id: a.accept_timeout for a in plan.offered_actions}
    rel = reliability_for(plan, LinkConfig(64, 0.2))
    assert set(commands) <= rel.heads.numbered and rel.deadlines[20] == plan.services[0].timeout


def test_without_a_mac_the_bridge_keeps_the_commands_copies(demo):
    plan = dataclasses.replace(BridgePlan.from_package(demo, "surface"), mac=None)
    assert reliable_commands(plan) == {}
    assert 20 not in reliability_for(plan, LinkConfig(64, 0.2)).heads.numbered


def test_on_a_wire_format_1_link_the_bridge_keeps_the_copies_whatever_the_mac(demo):
    plan = BridgePlan.from_package(demo, "surface")
    rmw_topic = dataclasses.replace(plan.topics[0], profile="rmw_desert")
    plan = dataclasses.replace(plan, outgoing_topics=[rmw_topic, *plan.outgoing_topics[1:]])
    assert plan.wire_format == 1 and plan.mac.mode == "turns"
    assert reliable_commands(plan) == {}
