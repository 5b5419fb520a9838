"""When a command message's copy is due (docs/wire-format.md section 15.6, docs/seams.md
section 7): a request, a goal or a result that waits for its answer (response, goal answer,
result acknowledgement) is sent again, same bytes, until the answer comes or its deadline.

- Never while an equal payload still waits in the link: it has not left, so a copy would
  ride the same packet (`Wiring.offer_once` offers nothing then).
- Under the turns MAC, once per round: a copy is due when the own turn that carried the
  message (or its last copy) has ended. The peer's turn follows that end, so its answer is
  then on its way or lost, and the copy, offered at once, waits in the link through the
  peer's turn and leaves first thing in the next own turn, unless the answer came
  meanwhile: the answer takes the copy back (`Wiring.withdraw`) before it uses air time.
  A timer cannot do this: a round is a turn and the peer's turn (seconds, and longer when a
  turn is missed), and a copy timed on it leaves just before its answer or a round late.
- Other MACs (none, TDMA): the retransmission timer (`uwgen.runtime.delivery.reliable
  .command_rtt`); when it fires while the message still waits in the link, the copy is put
  off by one more timeout. A packet told lost (`uwgen.bridge.fates`) makes it due at once.
- A copy that falls due after the peer's report told the message arrived is spared once
  (`Fates.spare`): its answer is on its way, or repaired by the side that has it.

`Leg` is what the parts keep of each message waiting for its answer: `next_send` (the
timer) and `turn` (the own turns ended while it, or its last copy, still waited in the link).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Protocol

if TYPE_CHECKING:
    from uwgen.bridge.wiring import Wiring


class Leg(Protocol):
    next_send: float
    turn: int | None


def copy_due(w: Wiring, key: int, payload: bytes, leg: Leg, now: float, rto: float) -> bool:
    """True when the copy of `payload` (channel `key`) is to be offered now (module doc);
    `rto`: the timer's next wait, used when it fires while the message still waits."""
    turns = w.turns()
    if turns is None:
        if leg.next_send > now and not w.fates.lost(key, payload):
            return False
        if w.waiting(key, payload) or w.fates.spare(key, payload):
            leg.next_send = now + rto        # not left yet, or arrived: no copy behind it
            return False
        return True
    if w.waiting(key, payload) or leg.turn is None:
        leg.turn = turns                     # still waiting for an own turn to carry it
        return False
    if turns <= leg.turn:
        return False                         # the turn that carried it has not ended
    leg.turn = turns                         # the copy waits from now for the next own turn
    return not w.fates.spare(key, payload)


def own_turns(mac) -> Callable[[], int | None]:
    """How many own turns have ended on this side under the turns MAC (the leader's grants
    sent, a follower's ends sent; `uwgen.runtime.link.mac.TurnMac.counts`): the rounds a
    copy is timed on. None under any other MAC (the timer)."""
    if getattr(mac, "mode", "none") != "turns":
        return lambda: None
    counts, key = mac.counts, "grants_sent" if mac.leading else "turns"
    return lambda: counts[key]
