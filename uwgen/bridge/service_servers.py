"""The serving side of bridged services: a client of the real service where the manifest's
server is here (`Servers`): request in from the link, response out.

A request can arrive before this bridge has discovered the real server (e.g. the first call
after both sides started): it then waits, in arrival order, until the server is ready
(bounded by WAIT_SHARE of the manifest timeout, counted from arrival, at most WAITING_LIMIT
requests per service) instead of being dropped; only then is it counted `no_server`. A copy
of a request already handled is never run again: its response, kept (RECENT_REPLIES), goes
again (`uwgen.bridge.services` has the calling side).
"""
from __future__ import annotations

from collections import OrderedDict
from typing import Any

from rclpy.task import Future

from uwgen.bridge.counters import ServiceCounters
from uwgen.bridge.dispatch import Dispatcher
from uwgen.bridge.outcomes import Handled, bare, query
from uwgen.bridge.plan import is_rmw_desert
from uwgen.bridge.wiring import Wiring
from uwgen.runtime.wire.codec import KIND_REQUEST, KIND_RESPONSE

WAIT_SHARE = 0.5      # of the manifest timeout a request may wait for the local server (the
                      # rest is for its trip and the response's: the caller's clock started
                      # before it was sent)
WAITING_LIMIT = 32    # requests per service waiting for the local server; more: no_server
RECENT_REPLIES = 32   # answered requests per service whose response is kept for a copy


class Servers:
    """Clients of the real services served on this side: request in, response out."""

    def __init__(self, wiring: Wiring, codecs: list[Any], counters: dict[int, ServiceCounters]):
        self.w = wiring
        self.codecs = codecs
        self.counters = counters
        self.served: dict[int, tuple[Any, Any]] = {}   # id -> (codec, client)
        self.serving: dict[int, dict[int, tuple[Future, float]]] = {}  # id -> seq -> call
        # id -> seq -> (request, deadline, began): requests waiting for the local server
        self.waiting: dict[int, dict[int, tuple[Any, float, float]]] = {}
        # id -> seq -> (response payload, when): answered requests, for copies of them
        self.replied: dict[int, OrderedDict[int, tuple[bytes, float]]] = {}
        # seqs handed to the local server (outcome queries), with when their calls began
        # (Wiring.began: the caller's deadline is that + the timeout)
        self.handled = Handled()
        for codec in codecs:
            counters[codec.id] = ServiceCounters()
            cls = wiring.ros_class(codec, "srv")
            if cls is None:
                continue
            client = wiring.node.create_client(cls, codec.name, callback_group=wiring.main_group)
            self.served[codec.id] = (codec, client)
            wiring.loops.watch_server(codec.name)
            self.serving[codec.id] = {}
            self.waiting[codec.id] = {}
            self.replied[codec.id] = OrderedDict()

    def register(self, dispatcher: Dispatcher) -> None:
        for ident in self.served:
            dispatcher.route(KIND_REQUEST, ident, self.serve)
            dispatcher.sends(KIND_RESPONSE, ident)

    def serve(self, ident: int, payload: bytes) -> None:
        codec, client = self.served[ident]
        counters = self.counters[ident]
        head = bare(payload)
        if head is not None and head[0] == 2 and not is_rmw_desert(codec):
            self._outcome(ident, head[2])
            return
        try:
            seq, request = codec.decode_request(payload)
        except ValueError as exc:
            counters.decode_errors += 1
            self.w.say_once(f"dreq{ident}", f"{codec.name}: request dropped, does not decode: {exc}")
            return
        counters.requests += 1
        if self.w.loops.blocked(codec.name):
            counters.loop_guard += 1      # our call would reach another bridge's stand-in
            return
        if seq in self.serving[ident] or seq in self.waiting[ident]:
            counters.duplicate_requests += 1
            return
        now = self.w.clock.now()
        handled = self.handled.when(ident, seq)         # when its call began
        if handled is not None and now - handled < 2 * codec.timeout:
            # A copy (its response was lost): never run again. A copy is never older than
            # the call's timeout (the link refuses it, wire-format 15.5); twice that covers
            # a far restart's new calls reusing the seq (a random start in 2^16).
            counters.duplicate_requests += 1
            replied = self.replied[ident].get(seq)
            if replied is not None:
                counters.repeated_replies += 1
                self.w.offer_once(ident, replied[0],                # not twice in one packet
                                  again=self.w.answer_urgent(handled, codec.timeout))
            return
        if not client.service_is_ready():
            if len(self.waiting[ident]) >= WAITING_LIMIT:
                counters.no_server += 1
                self.w.throttle.report(f"noserver{ident}", f"{codec.name}: request seq {seq} not "
                                       f"served: no local server and {WAITING_LIMIT} requests "
                                       "already wait for one (the caller times out)")
                return
            counters.waited += 1
            self.waiting[ident][seq] = (request, now + WAIT_SHARE * codec.timeout,
                                        self.w.began(payload, now))
            return
        self._call(ident, seq, request, now + codec.timeout, self.w.began(payload, now))

    def _outcome(self, ident: int, seq: int) -> None:
        """An outcome query: the response again, 'did not run' (`[3, id, seq]`), or nothing
        (running still, or ran without a response to give)."""
        replied = self.replied[ident].get(seq)
        if replied is not None:
            reply = replied[0]
        elif seq in self.serving[ident] or seq in self.waiting[ident] or (ident, seq) in self.handled:
            return
        else:
            reply = query(3, ident, seq)
        if self.w.send(ident, reply):
            self.counters[ident].outcome_answers += 1

    def _call(self, ident: int, seq: int, request: Any, deadline: float, began: float) -> None:
        self.handled.add(ident, seq, began)
        future = self.served[ident][1].call_async(request)
        self.serving[ident][seq] = (future, deadline)
        future.add_done_callback(lambda f: self._reply(ident, seq, f))

    def _serve_waiting(self, now: float) -> None:
        """Call the requests whose server has appeared; give up those past their deadline."""
        for ident, waiting in self.waiting.items():
            if not waiting:
                continue
            codec, client = self.served[ident]
            ready = client.service_is_ready()
            for seq, (request, wait_until, began) in list(waiting.items()):
                if ready:
                    del waiting[seq]
                    self._call(ident, seq, request, now + codec.timeout, began)
                elif wait_until <= now:
                    del waiting[seq]
                    self.counters[ident].no_server += 1
                    self.w.throttle.report(
                        f"noserver{ident}", f"{codec.name}: request seq {seq} not served: no local "
                        f"server appeared within {WAIT_SHARE * codec.timeout:g} s (the caller "
                        "times out)")

    def _reply(self, ident: int, seq: int, future: Future) -> None:
        codec, _ = self.served[ident]
        counters = self.counters[ident]
        log = self.w.log
        entry = self.serving[ident].get(seq)
        if entry is None or entry[0] is not future:
            return  # already timed out
        del self.serving[ident][seq]
        if future.cancelled():
            return
        exc = future.exception()
        if exc is not None:
            counters.server_errors += 1
            self.w.throttle.report(f"srverr{ident}", f"{codec.name}: local call for seq {seq} failed: {exc}")
            return
        try:
            payload = codec.encode_response(seq, future.result())
        except ValueError as exc:
            counters.server_errors += 1
            self.w.throttle.report(f"srvenc{ident}", f"{codec.name}: response for seq {seq} cannot be encoded: {exc}")
            return
        replied = self.replied[ident]
        replied[seq] = (payload, self.w.clock.now())
        replied.move_to_end(seq)
        while len(replied) > RECENT_REPLIES:
            replied.popitem(last=False)
        began = self.handled.when(ident, seq)
        if began is None:
            began = self.w.began(b"", self.w.clock.now())
        # the request came late (its first copies were lost): the response is the call's last
        # leg with too few rounds left to repair it, and gets its copy in its turn
        if self.w.offer_once(ident, payload, again=self.w.answer_urgent(began, codec.timeout)):
            counters.replies += 1
            # a lost response goes again at once, within the call's time (fates.py)
            self.w.fates.repairable(ident, payload, self.w.callers_deadline(began, codec.timeout))
        else:
            counters.reply_refused += 1
            self.w.throttle.report(f"srvref{ident}", f"{codec.name}: response for seq {seq} refused by the link")

    def expire(self) -> None:
        now = self.w.clock.now()
        self._serve_waiting(now)
        for ident, serving in self.serving.items():
            codec, client = self.served[ident]
            for seq, (future, deadline) in list(serving.items()):
                if deadline <= now:
                    del serving[seq]
                    client.remove_pending_request(future)
                    future.cancel()
                    self.counters[ident].server_timeouts += 1
                    self.w.throttle.report(f"srvtimeout{ident}", f"{codec.name}: local server did not "
                                           f"answer seq {seq} within {codec.timeout:g} s")
