"""What every bridge part is given: the rclpy node to create entities on, the link to send
on, the clock, the options, and the shared "said once" / "not bridged" bookkeeping.

The parts (topics, services, discovery, status, actions) never reach into the node or
into each other; the node builds one `Wiring` and hands it to each of them.
"""
from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Callable

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from uwgen.bridge.fates import Fates
from uwgen.bridge.loops import LoopGuard
from uwgen.bridge.plan import BridgeOptions
from uwgen.bridge.throttle import LogThrottle
from uwgen.manifest.model import Qos
from uwgen.runtime.clock import Clock

EXPECTED = 64                # copies an arriving answer may take back (Wiring.expect)
URGENT_ROUNDS = 2.5          # a command sent again with fewer MAC rounds left before its
                             # caller's deadline gets its copy in its turn (Wiring.urgent):
                             # a request or goal, whose answer must still come back
ANSWER_URGENT_ROUNDS = 2.0   # an answer (response, goal answer): the call's last leg
Send = Callable[..., bool]   # (id, payload, published=None) -> accepted


def qos_profile(qos: Qos) -> QoSProfile:
    """The manifest's QoS as an rclpy profile (keep-last history of `depth`)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=max(1, int(qos.depth)),
        reliability=(ReliabilityPolicy.BEST_EFFORT if qos.reliability == "best_effort"
                     else ReliabilityPolicy.RELIABLE),
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if qos.durability == "transient_local"
                    else DurabilityPolicy.VOLATILE))


@dataclass
class Wiring:
    node: Any                      # the rclpy Node the parts create their entities on
    send: Send                     # the link's offer(id, payload[, published]) -> accepted
    clock: Clock
    options: BridgeOptions
    log: Any                       # the node's rclpy logger
    main_group: Any                # mutually exclusive callback group (executor thread)
    service_group: Any             # reentrant group: stand-in calls await futures
    unavailable: dict[str, str] = field(default_factory=dict)  # entry name -> why not bridged
    wall: Callable[[], float] = time.time   # the system clock ROS stamps messages with
    recorder: Any = None           # uwgen.bridge.recorder.BridgeRecorder with --record
    round_trip: float | None = None  # what the MAC expects a request and its answer to take
    turn_gap: float = 0.0            # the MAC's longest wait for the peer's turn (runtime.link.mac)
    # a round as the MAC measures it (Mac.round: under turns the spacing of own turns);
    # None: `turn_gap`. Commands' urgency counts their rounds left in it (`urgent`)
    measured_round: Callable[[], float] | None = None
    # when a message offered at a time can next leave (Mac.next_turn: its side's next turn)
    next_turn: Callable[[float], float] = lambda now: now
    # the link's queue, set once the link exists (uwgen.bridge.copies): whether an equal
    # payload still waits in a channel, taking one back, and the own turns ended (None: no turns)
    waiting: Callable[[int, bytes], bool] = lambda key, payload: False
    withdraw: Callable[[int, bytes], bool] = lambda key, payload: False
    turns: Callable[[], int | None] = lambda: None
    # the link's reliability: a command offered again gets a copy in its turn (echoes.py)
    repeat: Callable[[int, bytes], None] = lambda key, payload: None
    # when a command that came began on its caller's side, from its age item (the link's
    # judge: runtime.delivery.judge.AgeJudge.began); None when the link cannot tell
    began_at: Callable[[bytes], float | None] = lambda payload: None
    # what the peer's reports told of our command messages (fates.py; made in __post_init__),
    # and whether the link has reports (wire format 2): they acknowledge a result's arrival
    fates: Fates = field(init=False)
    reports: bool = False
    # answer head -> (key, copy): a copy the answer takes back on arrival (take_back)
    answered_by: OrderedDict = field(default_factory=OrderedDict)
    said: set[str] = field(default_factory=set)
    throttle: LogThrottle = field(init=False)  # error lines a remote peer can cause: bounded
    loops: LoopGuard = field(init=False)       # services/actions another bridge here handles

    def __post_init__(self) -> None:
        self.throttle = LogThrottle(self.log.error, self.clock, warn=self.log.warning)
        self.loops = LoopGuard(self.node, self.log)
        self.fates = Fates(self.clock, lambda key, payload: self.withdraw(key, payload),
                           lambda key, payload, until: self.offer_once(
                               key, payload, again=self.urgent(until, answer=True)),
                           self.copy_awaiting)

    def offer_once(self, key: int, payload: bytes, again: bool = False) -> bool:
        """Offer a command message unless an equal one still waits in the link (it would
        ride the same packet: one is enough); True when it is queued either way. `again`:
        the peer asked for it again (its first was lost): the link copies it in its turn."""
        if again:
            self.repeat(key, payload)
        return self.waiting(key, payload) or self.send(key, payload)

    def copy_awaiting(self, key: int, payload: bytes, deadline: float, answer: bytes,
                      published: float | None = None) -> bool:
        """Under turns, a request, goal or result awaiting its answer (`answer`: the head it
        starts with) told lost: offered again at once, on the link's thread, so it is in the
        link before the own turn that follows the report builds its first packet (copies.py);
        its age item counts from `published` (its call's start, as every copy's), its answer
        takes it back, and it gets a copy in its turn when urgent (`urgent_copy`), also when an
        equal copy already waits in the link. False on a timer (no turns): `copy_due` sends it."""
        if self.turns() is None:
            return False
        if not self.waiting(key, payload) and not self.send(key, payload, published=published):
            return False
        # a copy already waiting (due by the round before the report came) is the repair: it
        # too gets its copy in its turn when urgent now
        self.expect(answer, key, payload, echo=self.urgent_copy(key, payload, deadline))
        return True

    def urgent_copy(self, key: int, payload: bytes, deadline: float | None) -> bool:
        """Whether a copy of a message awaiting its answer is urgent (`urgent`): on its own
        `deadline` (None: far off, a result's), or, for a result standing in for its goal's
        answer (fates.py `stands_in`), on that answer's deadline, as the answer's repair."""
        answers = self.fates.stands_in(key, payload)
        return ((deadline is not None and self.urgent(deadline))
                or (answers is not None and self.urgent(answers, answer=True)))

    def urgent(self, deadline: float, answer: bool = False) -> bool:
        """Whether a command sent again now has too few rounds of the MAC (`turn_gap`: a round
        of turns, a TDMA frame) left before `deadline`, its caller's, to repair another loss:
        then it also gets a copy in its own turn (uwgen.runtime.delivery.echoes), so the leg
        fails about 1 time in 25 at 20 % loss, not 1 in 5. A lost copy is known a round later
        (the peer's report) and sent again in the next own turn, so a request or goal needs
        that round and its answer's leg besides (half a round and a trip): URGENT_ROUNDS; an
        `answer` (a service's response, a goal's answer: the serving side's repair) is the
        call's last leg and needs that much less, ANSWER_URGENT_ROUNDS (half a round of it
        kept as a margin for a turn lost on the way). Earlier repairs go alone: a call has
        rounds left for them, and a copy of every repair cost a third of the bytes written
        (docs/wire-format.md section 15.6). Never without a MAC (no turn). Rounds are the
        MAC's measured ones (`measured_round`), not its bound `turn_gap`: under turns the
        bound was 3.3 s where rounds took 2.5 s (commands_bench), and counted in it nearly
        every command sent a second time was urgent. They are counted from when the message
        can leave (`next_turn`): a copy offered as its own turn ends waits a round for the
        next."""
        rounds = ANSWER_URGENT_ROUNDS if answer else URGENT_ROUNDS
        gap = self.turn_gap if self.measured_round is None else self.measured_round()
        return deadline - self.next_turn(self.clock.now()) < rounds * gap

    def answer_urgent(self, began: float, timeout: float) -> bool:
        """Whether the serving side's answer to a request or goal whose call began at `began`
        (`began`; the caller's `timeout`), given now, is urgent (`urgent`, an answer)."""
        return self.urgent(self.callers_deadline(began, timeout), answer=True)

    def wall_at(self, t: float) -> float:
        """The system clock's reading (what ROS stamps with; a restart does not reset it) at
        `t` on the bridge's clock."""
        return self.wall() - (self.clock.now() - t)

    def began(self, payload: bytes, came: float) -> float:
        """When the call of a request or goal `payload`, come at `came`, began on its
        caller's side, as the serving side can tell it: from the age item of the copy that
        came (every copy carries its call's age: docs/wire-format.md section 15.6), so a
        call whose first copies were lost is known that much older; else (no age item, or a
        payload the link's judge did not keep) its arrival less half a round of the MAC and
        a trip (it waited for its side's turn, then crossed: (`turn_gap` + `round_trip`) / 2)."""
        began = self.began_at(payload)
        if began is not None:
            return min(began, came)
        return came - (self.turn_gap + (self.round_trip or 0.0)) / 2

    def may_predate(self, payload: bytes, instant: float) -> bool | None:
        """Whether the call of a request or goal `payload` that came began before `instant`,
        as its age item tells (`began_at`: its likely beginning; the offset's error is not
        counted, or every goal sent just after a start would count). None when the link
        cannot tell (no age item: wire format 1; or a payload the judge no longer keeps)."""
        began = self.began_at(payload)
        return None if began is None else began < instant

    @staticmethod
    def callers_deadline(began: float, timeout: float) -> float:
        """The caller's deadline for a call that began at `began` (`began`)."""
        return began + timeout

    def expect(self, answer: bytes, key: int, copy: bytes, echo: bool = True) -> None:
        """A copy `copy` (channel `key`) was offered: the payload arriving that starts with
        `answer` (its response, goal answer or result, or a result's acknowledgement) takes
        it back if it still waits (uwgen.bridge.copies). The last EXPECTED are kept. The
        link copies it once more in its turn (uwgen.runtime.delivery.echoes) unless not `echo`."""
        if echo:
            self.repeat(key, copy)
        self.answered_by[answer] = (key, copy)
        self.answered_by.move_to_end(answer)
        while len(self.answered_by) > EXPECTED:
            self.answered_by.popitem(last=False)

    def take_back(self, payload: bytes) -> None:
        """On the link's thread, as a payload arrives: the copies it answers are taken back
        before the turn it opens builds its packets (the executor sees the answer later)."""
        for answer, (key, copy) in list(self.answered_by.items()):
            if payload.startswith(answer):
                self.answered_by.pop(answer, None)
                self.withdraw(key, copy)

    def say_once(self, key: str, text: str) -> None:
        """Log the first occurrence of a kind of problem; later ones are counted only."""
        if key not in self.said:
            self.said.add(key)
            self.log.error(text + " (further ones are counted in ~/status)")

    def ros_class(self, codec: Any, kind: str = "msg") -> Any | None:
        """The rclpy class of an entry (`kind` msg, srv or action), or None (logged, and
        reported in ~/status) when rclpy has no type support for it here (e.g. the codec
        fell back to its generated plain class)."""
        from rclpy.type_support import check_for_type_support
        try:
            cls = codec.ros_class()
            check_for_type_support(cls)
            if kind == "srv" and not hasattr(cls, "Request"):
                raise TypeError(f"{cls!r} is not a service type")
            if kind == "action" and not hasattr(cls, "Goal"):
                raise TypeError(f"{cls!r} is not an action type")
        except Exception as exc:  # ImportError, AttributeError, NoTypeSupportImportedException
            why = f"{type(exc).__name__}: {exc}".split(" This might be a ROS 1")[0]
            self.unavailable[codec.name] = why
            self.log.error(f"{codec.name} ({codec.type_name}) is not bridged: rclpy has no type "
                           f"support for it here ({why})")
            return None
        return cls
