"""When a command message's copy is due (docs/wire-format.md section 15.6, docs/seams.md
section 7): a request, a goal or a result that waits for its answer (response, goal answer,
result acknowledgement) is sent again, same bytes, until the answer comes or its deadline.

- Never while an equal payload still waits in the link: it has not left, so a copy would
  ride the same packet (`Wiring.offer_once` offers nothing then).
- Under the turns MAC, by the round: the peer's turn follows the end of the own turn that
  carried the message (or its last copy), and its report tells the message's fate
  (`uwgen.bridge.fates`). Told lost, the copy is due at once and leaves in the next own
  turn; told arrived, none is (the answer is on its way, or repaired by the side that has
  it). When nothing was told (the report rode a packet that was lost: most often the
  peer's first, with the answer), the message arrived four times in five, and the peer's
  next report tells again (its bitmap reaches back to its last report known to have
  arrived), so the copy waits one more round: it is due once the next own turn has ended
  too. A result, with no near deadline, waits two (`NEWS_ROUNDS`): the client side reports
  it again on its news, every second round, when no command of the server side asks sooner;
  one that stands in for its goal's answer (`Fates.stands_in`) has the answer's deadline:
  it waits as long, unless urgent on it (a serving side's message is the call's last leg:
  one sent blind after one round went to a client side that had it one time in four). A
  message told arrived before (its answer keeps being lost, or the peer's judge
  refused it) is copied every round but the one its arrival spared. A command already
  urgent (`Wiring.urgent`, its `deadline`) does not wait: its copy is offered as soon as its
  own turn has ended, waits in the link through the peer's turn and leaves first thing in
  the next own turn, unless its answer or its arrival came meanwhile and took it back
  (`Wiring.withdraw`) before it used air time. A timer cannot do this: a round is a turn
  and the peer's turn (seconds, and longer when a turn is missed), and a copy timed on it
  leaves just before its answer or a round late.
- Other MACs (none, TDMA): the retransmission timer (`uwgen.runtime.delivery.reliable
  .command_rtt`); when it fires while the message still waits in the link, the copy is put
  off by one more timeout. A packet told lost (`uwgen.bridge.fates`) makes it due at once.
  A result (no near deadline) whose timer fires the first time with nothing told waits one
  more timeout (`held`), as under turns it waits a round more: the report that named it
  was most often lost, and the peer's next report names it again (its bitmap reaches back
  to its last report known to have arrived). Sent at once instead, such copies went to a
  peer that had the result for 10-14 results in 100 at 20 % loss under TDMA (one standing in
  for its goal's answer is held unless urgent on it). A request or goal is not held: its
  copy, sent when its answer was lost, went to a peer that had it about one time in two
  under TDMA, but held, a request lost with the report that would have told it waited a
  frame more, and two calls in 100 failed so (seed 113).
- A copy that falls due after the peer's report told the message arrived is spared once
  (`Fates.spare`): its answer is on its way, or repaired by the side that has it.

`Leg` is what the parts keep of each message waiting for its answer: `next_send` (the
timer) and `turn` (the own turns ended while it, or its last copy, still waited in the link).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Protocol

if TYPE_CHECKING:
    from uwgen.bridge.wiring import Wiring


# Rounds a message with no near deadline (a result: `result_timeout`, many rounds) waits,
# when nothing was told, for what the peer's reports say: when the report that named it was
# lost and no command of ours asks for another, the peer reports its news every second round
# (`ack_interval`, docs/wire-format.md section 15.2).
NEWS_ROUNDS = 2


class Leg(Protocol):
    next_send: float
    turn: int | None
    held: bool


def copy_due(w: Wiring, key: int, payload: bytes, leg: Leg, now: float, rto: float,
             deadline: float | None = None, answer: bool = False) -> bool:
    """True when the copy of `payload` (channel `key`) is to be offered now (module doc);
    `rto`: the timer's next wait, used when it fires while the message still waits;
    `deadline`: its caller's (None: far off, as a result's; a result standing in for its
    goal's answer has the answer's), `answer`: the call's last leg (`Wiring.urgent`; under
    turns it waits NEWS_ROUNDS for a report, as a result alone does, unless urgent)."""
    turns = w.turns()
    if turns is None:
        lost = w.fates.lost(key, payload)
        if leg.next_send > now and not lost:
            return False
        if w.waiting(key, payload) or w.fates.spare(key, payload):
            leg.next_send = now + rto        # not left yet, or arrived: no copy behind it
            return False
        if not lost and not leg.held and (
                deadline is None or (answer and not w.urgent(deadline, answer=answer))):
            leg.held = True                  # nothing told: the report naming it was lost,
            leg.next_send = now + rto        # and the peer's next one names it again
            return False
        return True
    if w.waiting(key, payload) or leg.turn is None:
        leg.turn = turns                     # still waiting for an own turn to carry it
        return False
    if turns <= leg.turn:
        return False                         # the turn that carried it has not ended
    if w.fates.lost(key, payload):
        leg.turn = turns                     # told lost: the next own turn carries the copy
        return True
    if w.fates.spare(key, payload):
        leg.turn = turns                     # told arrived: no copy this round
        return False
    rounds = 1 if deadline is not None and not answer else NEWS_ROUNDS
    if turns <= leg.turn + rounds and not w.fates.arrived(key, payload) \
            and not (deadline is not None and w.urgent(deadline, answer=answer)):
        return False                         # nothing told yet: the peer's next report will
    leg.turn = turns                         # the copy waits from now for the next own turn
    return True


def own_turns(mac) -> Callable[[], int | None]:
    """How many own turns have ended on this side under the turns MAC (the leader's grants
    sent, a follower's ends sent; `uwgen.runtime.link.turn_mac.TurnMac.counts`): the rounds a
    copy is timed on. None under any other MAC (the timer)."""
    if getattr(mac, "mode", "none") != "turns":
        return lambda: None
    counts, key = mac.counts, "grants_sent" if mac.leading else "turns"
    return lambda: counts[key]
