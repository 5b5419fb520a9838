"""What the peer's reports tell of this side's command messages (docs/wire-format.md section
15.6, "A command's fate"): a request, goal, answer or result arrived, or its packet was lost.

The link numbers every packet and the peer reports which arrived (section 15.2); the link
knows which messages each packet carried, so it tells the bridge each command message's fate
(`uwgen.runtime.delivery.reliability.Reliability.on_fate`, on the link's thread). A copy sent
blind each round (`uwgen.bridge.copies`) repairs a lost request and a lost answer alike, by
sending the request again; told fates let each side repair its own leg, as LTP's report
segments let a sender retransmit exactly what is missing:

- **arrived**: an equal payload still waiting in the link is a copy nobody needs (the peer
  has the message, and answers from what it keeps): it is taken back before it leaves
  (`spared`). Told too late for that (the copy was not offered yet), the arrival spares the
  next copy that falls due (`copy_due` asks `spare`): once per arrival, so a message whose
  answer keeps being lost still goes again every other round, a fallback for what the link
  cannot see (the peer's judge refused it; its bridge started again). A result told arrived
  is acknowledged as by the client side's word (`uwgen.bridge.action_servers`): the client side
  has it, or asks for it again (section 13, *result status*);
- **lost**: an answer (a service's response, a goal's answer) is offered again by the side
  that has it (`repairable`, until its caller's deadline), at once: the caller need not send
  its request again for it (`repaired`); not a goal's answer once its result was offered
  (`answered_by`: the result says accepted, and goes again itself; until the answer is
  told arrived, the result's copies are timed on the answer's deadline, `stands_in`, as the
  answer's own repair was: it is the goal's last leg). A request, goal or
  result still waiting for its answer (`awaiting`) is offered again at once too, on the
  link's thread (`copied`), so that under turns it is in the link before the own turn that
  follows the report builds its first packet; when that copy is not taken (no turns: the
  timer decides), it is due again at once under a timer (`copy_due` asks `lost`) instead of
  after its timeout.

A fate names a message by its bytes as the bridge offered them (no head): a command's bytes
are unique while it is alive (its seq or handle), and what is kept is bounded (KEPT).
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable

from uwgen.runtime.clock import Clock

KEPT = 256            # fates and repairable answers remembered (a turn carries a few)


class Fates:
    """The fates told of this side's command messages, and the answers it repairs."""

    def __init__(self, clock: Clock, withdraw: Callable[[int, bytes], bool],
                 offer_again: Callable[[int, bytes, float], bool],
                 copy_again: Callable[[int, bytes, float, bytes, float | None], bool] =
                 lambda k, p, until, answer, published: False):
        self.clock, self.withdraw, self.offer_again = clock, withdraw, offer_again
        self.copy_again = copy_again    # a message awaiting its answer, told lost: offered?
        self._lock = threading.Lock()
        # told arrived -> whether that arrival may still spare a copy (`spare`, once)
        self._arrived: OrderedDict[tuple[int, bytes], bool] = OrderedDict()
        self._lost: OrderedDict[tuple[int, bytes], bool] = OrderedDict()
        self._repairable: OrderedDict[tuple[int, bytes], float] = OrderedDict()   # -> until
        # a request, goal or result waiting for its answer -> (until, whether it still waits,
        # its answer's head, when its call began)
        self._awaiting: OrderedDict[tuple[int, bytes],
                                    tuple[float, Callable[[], bool], bytes, float | None]] = OrderedDict()
        # a result standing in for its goal's answer (`answered_by`) -> (that answer, its
        # caller's deadline)
        self._standing: OrderedDict[tuple[int, bytes], tuple[bytes, float]] = OrderedDict()
        self.counts = {"arrived": 0, "lost": 0, "spared": 0, "repaired": 0, "copied": 0}

    def told(self, key: int, payload: bytes, arrived: bool) -> None:
        """The link's report: `payload` (channel `key`) arrived, or its packet was lost. On
        the link's thread."""
        item = (key, bytes(payload))
        if arrived:
            spared = self.withdraw(key, item[1])          # a copy waiting: not needed
            with self._lock:
                self.counts["arrived"] += 1
                self._lost.pop(item, None)
                self._repairable.pop(item, None)          # the peer has it: nothing to repair
                self._awaiting.pop(item, None)
                self._standing.pop(item, None)
                self.counts["spared"] += spared
                _remember(self._arrived, item, not spared)
            return
        with self._lock:
            self.counts["lost"] += 1
            now = self.clock.now()
            until = self._repairable.get(item)
            repair = until is not None and now < until
            waits = self._awaiting.get(item)
        if repair:
            if self.offer_again(key, item[1], until):
                with self._lock:
                    self.counts["repaired"] += 1
            return
        if waits is not None:
            deadline, alive, answer, published = waits
            if now < deadline and alive() and self.copy_again(key, item[1], deadline, answer,
                                                               published):
                with self._lock:
                    self.counts["copied"] += 1
                return
        with self._lock:
            _remember(self._lost, item, True)

    def forget(self, key: int, payload: bytes) -> None:
        """`payload` is offered anew (a new goal or result may repeat an old one's bytes on a
        reused handle): what was told of earlier ones is not about it."""
        with self._lock:
            item = (key, bytes(payload))
            for table in (self._arrived, self._lost, self._repairable, self._awaiting,
                          self._standing):
                table.pop(item, None)

    def arrived(self, key: int, payload: bytes) -> bool:
        """Whether the peer's reports told that `payload` arrived since it was offered anew."""
        with self._lock:
            return (key, bytes(payload)) in self._arrived

    def repairable(self, key: int, payload: bytes, until: float) -> None:
        """An answer this side sent: offered again when its packet is told lost, until
        `until` (its caller's deadline)."""
        with self._lock:
            item = (key, bytes(payload))
            self._arrived.pop(item, None)
            self._repairable[item] = until
            self._repairable.move_to_end(item)
            while len(self._repairable) > KEPT:
                self._repairable.popitem(last=False)

    def awaiting(self, key: int, payload: bytes, until: float, alive: Callable[[], bool],
                 answer: bytes, published: float | None = None) -> None:
        """A request, goal or result this side sent waits for its answer (whose payload starts
        with `answer`) until `until` (its deadline), while `alive()` (read on the link's
        thread): told lost, it is offered again at once (`copy_again`), its age item counted
        from `published` (its call's start; None: now)."""
        with self._lock:
            item = (key, bytes(payload))
            self._awaiting[item] = (until, alive, bytes(answer), published)
            self._awaiting.move_to_end(item)
            while len(self._awaiting) > KEPT:
                self._awaiting.popitem(last=False)

    def answered_by(self, key: int, payload: bytes, by: bytes, until: float | None = None) -> None:
        """A later message `by` answers for `payload` (a goal's result: the client side takes
        it as the goal's acceptance, section 13): told lost now, `payload` is not offered
        again. Until `payload` is told arrived, `by` stands in for it up to `until`, the
        caller's deadline for it (`stands_in`; None: it need not)."""
        with self._lock:
            self._repairable.pop((key, bytes(payload)), None)
            if until is not None:
                _remember(self._standing, (key, bytes(by)), (bytes(payload), until))

    def stands_in(self, key: int, payload: bytes) -> float | None:
        """The deadline of the answer `payload` stands in for (`answered_by`), while that
        answer is not told arrived and its deadline is ahead; else None. Its copies are
        timed on it: a result that is also its goal's acceptance is as urgent as the answer
        was (`uwgen.bridge.wiring.Wiring.urgent`)."""
        with self._lock:
            got = self._standing.get((key, bytes(payload)))
            if got is None or (key, got[0]) in self._arrived or self.clock.now() >= got[1]:
                return None
            return got[1]

    def spare(self, key: int, payload: bytes) -> bool:
        """True, once per arrival told, when a copy of `payload` falls due: the peer has it."""
        item = (key, bytes(payload))
        with self._lock:
            if not self._arrived.get(item):
                return False
            self._arrived[item] = False
            self.counts["spared"] += 1
            return True

    def lost(self, key: int, payload: bytes) -> bool:
        """True, once per loss told, when `payload`'s packet was lost: its copy is due now."""
        with self._lock:
            return self._lost.pop((key, bytes(payload)), False)

    def stats(self) -> dict[str, int]:
        with self._lock:
            return dict(self.counts)


def _remember(table: OrderedDict, item: tuple[int, bytes], value: bool) -> None:
    table[item] = value
    table.move_to_end(item)
    while len(table) > KEPT:
        table.popitem(last=False)
