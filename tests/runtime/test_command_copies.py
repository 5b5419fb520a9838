"""A command's copy in its own turn (uwgen.runtime.delivery.echoes; docs/wire-format.md
section 15.6): at a measured loss (or at a start, before the loss is known) a request, an
answer or a result the bridge sends again goes once more in the spare room of a later packet of the
same turn or slot, never later, never twice; under turns a lost packet then costs it
nothing. Explicit times, and two links on a ManualClock."""
from __future__ import annotations

from tests.runtime.turns_pair import SENDERS, turns_pair
from uwgen.manifest.model import LinkPolicy
from uwgen.runtime.delivery.copies import LOSS_WINDOW, MEASURED
from uwgen.runtime.delivery.echoes import Echoes
from uwgen.runtime.delivery.reliability import Reliability
from uwgen.runtime.wire.heads import Heads

CALL = 20                                   # a service's channel (requests and responses)
REQUEST = bytes((2, CALL, 7)) + bytes(12)   # kind 2, id 20, seq 7
RESPONSE = bytes((3, CALL, 7)) + bytes(12)


class _Lossy:
    """A link's measured loss (copies.Copies): copies wanted, the loss known."""

    def __init__(self, wanted: int = 1, measured: bool = True):
        self._wanted, self._measured = wanted, measured

    def wanted(self) -> int:
        return self._wanted

    def measured(self) -> bool:
        return self._measured


def echoes(window: float = 1.0, spare: _Lossy | None = None) -> tuple[Echoes, Heads]:
    heads = Heads(aged=frozenset({CALL}))
    return Echoes(frozenset({CALL}), window, heads, spare or _Lossy()), heads


def test_a_command_sent_again_gets_one_copy_in_its_own_turn_its_age_moved_on():
    e, heads = echoes()
    stamped, _ = heads.add(REQUEST, 0.5)
    e.repeat(CALL, REQUEST)                                 # the bridge's copy: its first was lost
    e.left(0, [(CALL, stamped)], 10.0)
    key, copy = e.pick(10.4, 64)
    assert key == CALL and heads.take(copy).payload == REQUEST
    assert heads.take(copy).age > heads.take(stamped).age  # 0.5 s old when it left, 0.4 s ago
    e.left(1, [(CALL, copy)], 10.4)                         # the copy left: not copied again
    assert e.pick(10.6, 64) is None and e.sent == {CALL: 1}


def test_a_command_sent_the_first_time_gets_no_copy_even_before_the_loss_is_known():
    for spare in (_Lossy(), _Lossy(0, measured=False)):     # lossy; a start, loss unknown
        e, heads = echoes(spare=spare)
        e.left(0, [(CALL, heads.add(REQUEST, 0.0)[0])], 0.0)
        assert e.pick(0.2, 64) is None and not e.waiting(0.2)
        e.repeat(CALL, RESPONSE)                             # sent again: copied, loss unknown
        e.left(1, [(CALL, heads.add(RESPONSE, 0.0)[0])], 0.3)
        assert e.waiting(0.4) and e.pick(0.4, 64) is not None


def test_no_copy_after_its_own_turn_or_where_it_does_not_fit():
    e, heads = echoes(window=1.0)
    e.repeat(CALL, REQUEST)
    e.left(0, [(CALL, heads.add(REQUEST, 0.0)[0])], 0.0)
    assert e.pick(0.5, 8) is None                           # no room: it waits
    assert e.waiting(0.5)
    assert e.pick(1.2, 64) is None and not e.waiting(1.2)   # the turn is over
    quiet, heads = echoes(spare=_Lossy(0))                  # no loss measured: none
    quiet.repeat(CALL, REQUEST)
    quiet.left(0, [(CALL, heads.add(REQUEST, 0.0)[0])], 0.0)
    assert not quiet.waiting(0.2)


def test_topics_feedback_and_a_cut_command_are_not_copied():
    e, heads = echoes(spare=_Lossy(measured=False))
    for key, payload in ((4, bytes((0, 4, 1))), (256 + CALL, bytes((0, CALL, 1))), (CALL, REQUEST)):
        e.repeat(key, payload)                              # sent again: none of these
    e.left(0, [(4, bytes((0, 4, 1))), (256 + CALL, bytes((0, CALL, 1)))], 0.0)
    assert e.pick(0.2, 64) is None                          # a topic, an action's feedback
    e.left(1, [(CALL, heads.add(REQUEST, 0.0)[0])], 0.2)
    e.cut(1)                                                # its tail went in packet 2
    assert e.pick(0.4, 64) is None


def command_link() -> Reliability:
    rel = Reliability(1, period=0.2, reliable={}, max_ages={CALL: 12.0}, max_read_length=64,
                      commands=frozenset({CALL}), own_span=1.0)
    rel.repeat(CALL, REQUEST)                               # the bridge sends it again
    rel.sent(0, [(CALL, rel.stamp(CALL, REQUEST, 0.0, 0.0))], 0.0)
    return rel


def test_the_link_copies_a_command_only_at_a_measured_loss_and_even_in_a_packet_of_parts_alone():
    rel = command_link()
    for _ in range(MEASURED):
        rel.engine.spare.settled(True)                      # measured: nothing lost
    assert rel.copy(0.2, 60) is None and rel.next_time(0.2) != 0.2
    for _ in range(LOSS_WINDOW // 10):
        rel.engine.spare.settled(False)
    assert rel.next_time(0.2) == 0.2                        # a packet of its turn for the copy
    key, copy = rel.copy(0.2, 60, fresh=False)              # a notice's, a grant's, an end's packet
    assert key == CALL and rel.stats()["reliability"]["command_copies"] == {CALL: 1}


def test_at_a_start_before_the_loss_is_known_a_command_sent_again_is_copied():
    rel = command_link()                                    # nothing settled yet: lossy
    assert rel.copy(0.2, 60) is not None
    rel.repeat(CALL, RESPONSE)
    for _ in range(MEASURED):
        rel.engine.spare.settled(True)
    rel.sent(1, [(CALL, rel.stamp(CALL, RESPONSE, 0.3, 0.3))], 0.3)
    assert rel.copy(0.5, 60) is None                        # known now: no loss, no copy


# -- two links under turns (a ManualClock) ----------------------------------------------------

def call_over_turns(lossy: bool):
    """A call at 5 s over turns at 1000 m; the surface's packet carrying the request is lost.
    Returns (surface packets carrying it, vehicle packets carrying the answer, each as
    (time, number), when the request reached the vehicle, the two links' reliabilities, the
    payloads the surface received)."""
    def settle(rel: Reliability) -> None:
        for k in range(LOSS_WINDOW):                 # measured: lossy (1 in 8) or not
            rel.engine.spare.settled(not (lossy and k % 8 == 0))
    sim, clock, rel = turns_pair(frozenset({CALL}), {CALL: 12.0}, settle)
    carried: dict[str, list[tuple[float, int]]] = {s: [] for s in SENDERS}
    for side, link in sim.links.items():
        sent = link.hooks.sent

        def spy(number, picked, now, side=side, sent=sent):
            if any(key == CALL for key, _ in picked):
                if side == "surface" and not carried[side]:
                    sim.drop(side, sim.written[side])       # the request's first packet is lost
                carried[side].append((now, number))
            return sent(number, picked, now)
        link.hooks.sent = spy
        link.add_channel(CALL, LinkPolicy(queue="fifo", depth=8, ttl=12.0))
    # the bridges' copies (a request sent again, its answer given again): the link copies
    # them in their turn
    rel["surface"].repeat(CALL, REQUEST)
    rel["vehicle"].repeat(CALL, RESPONSE)
    sim.at(5.0, lambda: sim.links["surface"].offer(CALL, REQUEST))
    got: list[float] = []

    def serve():                                # the vehicle's bridge answers the request
        if not got and any(p[:3] == REQUEST[:3] for _, p in sim.received["vehicle"]):
            got.append(clock.now())
            sim.links["vehicle"].offer(CALL, RESPONSE)
    for k in range(600):
        sim.at(0.05 * k, serve)
    sim.run(25.0)
    return carried["surface"], carried["vehicle"], got, rel, [p for _, p in sim.received["surface"]]


def test_under_turns_a_request_whose_packet_is_lost_arrives_in_the_same_turn_by_its_copy():
    sent, answers, got, rel, back = call_over_turns(lossy=True)
    span = rel["surface"].echoes.window
    assert len(sent) == 2 and sent[1][0] - sent[0][0] <= span    # the copy, in the same turn
    assert got and got[0] < sent[0][0] + span + 2.0             # it came before the next turn
    # the vehicle answered in its next turn, and copied the answer in the same turn
    assert len(answers) == 2 and answers[1][0] - answers[0][0] <= rel["vehicle"].echoes.window
    assert 1 <= sum(p[:3] == RESPONSE[:3] for p in back) <= 2  # the answer came (and its copy)


def test_without_a_measured_loss_a_lost_request_waits_for_the_bridges_copy():
    sent, answers, got, rel, back = call_over_turns(lossy=False)
    assert len(sent) == 1 and not got and not answers          # no copy: the call needs a round
    assert rel["surface"].stats()["reliability"]["command_copies"] == {}
