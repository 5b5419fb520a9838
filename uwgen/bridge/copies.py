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
- Under TDMA, once a frame, when the answer could no longer come: the link's MAC knows the
  ON window a message written now leaves in, and when every other side's next ON window has
  reached this side (`TdmaMac.answers`); once the message (or its last copy) has left the
  link, its copy is due then. The answer arrives before this side's next write window
  closes, so the copy still leaves in the next own slot, and an answer merely late in the
  peer's slot costs no copy. A timer cannot do this: the frame's phase drifts against it,
  its copy leaves just before a late answer, or misses a window and loses a frame.
- Other MACs (none, and TDMA while no phase is known): the retransmission timer
  (`uwgen.runtime.delivery.reliable.command_rtt`); when it fires while the message still
  waits in the link, the copy is put off by one more timeout.

`Leg` is what the parts keep of each message waiting for its answer: `next_send` (the
timer), `turn` (the own turns ended while it, or its last copy, still waited in the link)
and `answer_by` (TDMA: when the answer to its last departure is in; None while it waits).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Protocol

if TYPE_CHECKING:
    from uwgen.bridge.wiring import Wiring


class Leg(Protocol):
    next_send: float
    turn: int | None
    answer_by: float | None


def copy_due(w: Wiring, key: int, payload: bytes, leg: Leg, now: float, rto: float) -> bool:
    """True when the copy of `payload` (channel `key`) is to be offered now (module doc);
    `rto`: the timer's next wait, used when it fires while the message still waits."""
    turns = w.turns()
    if turns is None:
        if w.waiting(key, payload):
            leg.answer_by = None             # not left yet: no copy behind it
            if leg.next_send <= now:
                leg.next_send = now + rto
            return False
        if leg.answer_by is None:
            leg.answer_by = w.answer_by(now)     # TDMA: it left lately; None: the timer
        if leg.answer_by is None:
            return leg.next_send <= now
        if now < leg.answer_by:
            return False
        leg.answer_by = None                 # the copy: timed again once it has left
        return True
    if w.waiting(key, payload) or leg.turn is None:
        leg.turn = turns                     # still waiting for an own turn to carry it
        return False
    if turns <= leg.turn:
        return False                         # the turn that carried it has not ended
    leg.turn = turns                         # the copy waits from now for the next own turn
    return True


def own_turns(mac) -> Callable[[], int | None]:
    """How many own turns have ended on this side under the turns MAC (the leader's grants
    sent, a follower's ends sent; `uwgen.runtime.link.mac.TurnMac.counts`): the rounds a
    copy is timed on. None under any other MAC (the timer)."""
    if getattr(mac, "mode", "none") != "turns":
        return lambda: None
    counts, key = mac.counts, "grants_sent" if mac.leading else "turns"
    return lambda: counts[key]


def answer_time(mac) -> Callable[[float], float | None]:
    """When the answers to a message that left the link at about `now` have all come or been
    lost, under TDMA with a known phase (`uwgen.runtime.link.slot_timing.AnswerTimes`); None
    otherwise (the timer)."""
    if getattr(mac, "mode", "none") != "tdma":
        return lambda now: None
    return mac.answers.answer_by
