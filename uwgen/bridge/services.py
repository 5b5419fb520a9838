"""Bridged services of one side: stand-in services where the manifest's server is elsewhere
(`StandIns`; the real service's client where it is here is `uwgen.bridge.service_servers`).

A call crosses as `[2, id, seq, ...]` and comes back as `[3, id, seq, ...]`; the seqs and
deadlines of the calling side live in `uwgen.bridge.calls.CallTable`. Calls toward an
rmw_desert-profile service use seqs 1..999; an rmw_desert server may answer only the
latest of several outstanding requests, and the older calls then time out at their
deadline like any unanswered call (counted).

Failed bridged calls (see docs/demo.md, "Service calls"). ROS 2 services have no error
reply and rclpy cannot hand an exception to a remote client's future. When a bridged call
gets no response within the manifest timeout, or its request cannot be queued, the
stand-in service by default sends **no response**: the caller's future stays pending,
exactly as if the server had vanished, and its own timeout (`Client.call(timeout_sec=...)`
returns None; `call_async` futures stay not done) detects the failure. The bridge logs an
error naming the service and seq, and counts it (`timeouts`/`refused` in ~/status). With
`service_timeout_reply:=default` it instead returns a default-constructed response, for
callers that cannot live without a reply (indistinguishable from success for empty
responses, hence not the default).
"""
from __future__ import annotations

import random
from dataclasses import asdict, dataclass
from typing import Any, Callable

from rclpy.exceptions import InvalidHandle
from rclpy.task import Future

from uwgen.bridge.calls import RMW_DESERT_SEQ_RANGE, CallTable, CallTableFull
from uwgen.bridge.copies import copy_due
from uwgen.bridge.counters import ServiceCounters
from uwgen.bridge.dispatch import Dispatcher
from uwgen.bridge.outcomes import ASKS, Asking, bare, query
from uwgen.bridge.service_servers import Servers
from uwgen.bridge.plan import TIMEOUT_REPLY_DEFAULT, is_rmw_desert
from uwgen.bridge.wiring import Wiring
from uwgen.runtime.wire.codec import KIND_REQUEST, KIND_RESPONSE
from uwgen.runtime.delivery.reliable import RttEstimator, command_rtt



@dataclass
class Outgoing:
    """A request sent and not yet answered (calling side): sent again when a copy is due
    (uwgen.bridge.copies)."""

    payload: bytes
    first_sent: float
    next_send: float
    sends: int = 1
    turn: int | None = None          # own turns ended while it waited in the link (copies.py)
    held: bool = False               # timer: its first copy waited once more (copies.py)


def service_rtt(codec: Any, period: float, round_trip: float | None = None,
                turn_gap: float = 0.0) -> RttEstimator:
    """The retransmission timer of one service's requests (reliable.command_rtt)."""
    return command_rtt(codec.timeout, period, round_trip, turn_gap)


class StandIns:
    """Stand-in services for services served on another side: request out, response back."""

    def __init__(self, wiring: Wiring, codecs: list[Any], counters: dict[int, ServiceCounters],
                 rng: random.Random | None = None):
        self.w = wiring
        self.codecs = codecs
        self.counters = counters
        self.calls = CallTable(wiring.clock, rng=rng)
        self.called: dict[int, Any] = {}     # id -> codec
        self.outgoing: dict[tuple[int, int], Outgoing] = {}   # (id, seq) -> request in flight
        self.rtt: dict[int, RttEstimator] = {}
        self.services: dict[int, Any] = {}   # id -> the stand-in service (absent: withdrawn)
        self.asking: dict[tuple[int, int], Asking] = {}   # timed-out calls asked about
        for codec in codecs:
            counters[codec.id] = ServiceCounters()
            cls = wiring.ros_class(codec, "srv")
            if cls is None:
                continue
            self._offer(codec, cls)
            wiring.loops.watch_standin(codec.name,
                                       on_change=lambda blocked, c=codec, k=cls: self._loop(c, k, blocked))
            self.called[codec.id] = codec
            if is_rmw_desert(codec):
                self.calls.set_seq_range(codec.id, *RMW_DESERT_SEQ_RANGE)
            else:   # an rmw_desert server would run a copy again: never re-sent to one
                self.rtt[codec.id] = service_rtt(codec, wiring.options.link.period,
                                                 wiring.round_trip, wiring.turn_gap)

    def _offer(self, codec: Any, cls: Any) -> None:
        srv = self.w.node.create_service(cls, codec.name, self._standin(codec),
                                         callback_group=self.w.service_group)
        allow_no_response(srv, lambda: self._withdrawn_reply(codec))
        self.services[codec.id] = srv

    def _withdrawn_reply(self, codec: Any) -> None:
        self.counters[codec.id].answer_withdrawn += 1
        self.w.throttle.report(f"swithdrawn{codec.id}", f"{codec.name}: a response came after the "
                                                        "stand-in was withdrawn (another bridge in "
                                                        "this ROS graph): not delivered")

    def _loop(self, codec: Any, cls: Any, blocked: bool) -> None:
        """Withdraw the stand-in while another bridge here serves it (loops.py), and back."""
        if blocked and codec.id in self.services:
            self.w.node.destroy_service(self.services.pop(codec.id))
        elif not blocked and codec.id not in self.services:
            self._offer(codec, cls)

    def register(self, dispatcher: Dispatcher) -> None:
        for ident in self.called:
            dispatcher.route(KIND_RESPONSE, ident, self.complete)
            dispatcher.sends(KIND_REQUEST, ident)

    def _standin(self, codec: Any) -> Callable:
        counters = self.counters[codec.id]
        log = self.w.log

        async def call(request: Any, response: Any) -> Any:
            """One local call, timed for the recording when there is one."""
            recorder = self.w.recorder
            if recorder is None:
                return await call_once(request, response)
            start, answered = self.w.wall(), counters.responses
            result = await call_once(request, response)
            recorder.call(codec.name, start, self.w.wall(), counters.responses > answered)
            return result

        async def call_once(request: Any, response: Any) -> Any:
            counters.local_calls += 1
            if self.w.loops.blocked(codec.name):
                counters.loop_guard += 1
                return None       # never a response: the real server in this graph answers
            future = Future()
            try:
                pending = self.calls.begin(codec.id, codec.timeout, token=future)
            except CallTableFull as exc:
                counters.refused += 1
                log.error(f"{codec.name}: call refused: {exc}")
                return self._failed_reply(response)
            try:
                payload = codec.encode_request(pending.seq, request)
            except ValueError as exc:
                counters.encode_errors += 1
                self.calls.abandon(codec.id, pending.seq)
                log.error(f"{codec.name}: call failed, request cannot be encoded: {exc}")
                return self._failed_reply(response)
            self.w.fates.forget(codec.id, payload)
            if not self.w.send(codec.id, payload):
                counters.refused += 1
                self.calls.abandon(codec.id, pending.seq)
                log.error(f"{codec.name}: call seq {pending.seq} failed: the link refused "
                          "the request (queue full or too large; see ~/status)")
                return self._failed_reply(response)
            rtt = self.rtt.get(codec.id)
            if rtt is not None:
                now = self.w.clock.now()
                key = (codec.id, pending.seq)
                self.outgoing[key] = Outgoing(payload, now, now + rtt.rto, turn=self.w.turns())
                self.w.fates.awaiting(codec.id, payload, pending.deadline,
                                      lambda: key in self.outgoing, query(3, *key), now)
            result = await future
            if result is None:
                return self._failed_reply(response)
            counters.responses += 1
            return result
        return call

    def _failed_reply(self, response: Any) -> Any:
        # None: no response at all (see the module doc); the patched send_response skips it.
        return response if self.w.options.timeout_reply == TIMEOUT_REPLY_DEFAULT else None

    def complete(self, ident: int, payload: bytes) -> None:
        codec = self.called[ident]
        head = bare(payload)
        if head is not None and head[0] == 3 and (ident, head[2]) in self.asking:
            asked = self.asking.pop((ident, head[2]))
            self.counters[ident].not_run += 1
            self.w.log.info(f"{codec.name}: call seq {head[2]} (no response within "
                            f"{codec.timeout:g} s) did not run on the server side, and never will")
            return
        try:
            seq, resp = codec.decode_response(payload)
        except ValueError as exc:
            self.counters[ident].decode_errors += 1
            self.w.say_once(f"dresp{ident}",
                            f"{codec.name}: response dropped, does not decode: {exc}")
            return
        pending = self.calls.complete(ident, seq)
        asked = self.asking.pop((ident, seq), None)
        if pending is None and asked is not None:
            self.counters[ident].ran_after_timeout += 1
            self.w.log.warning(f"{codec.name}: call seq {seq} got no response within "
                               f"{codec.timeout:g} s, but it RAN on the server side (its response "
                               f"came {self.w.clock.now() - asked.called:.1f} s after the call; "
                               "counted ran_after_timeout)")
        outgoing = self.outgoing.pop((ident, seq), None)
        if outgoing is not None and outgoing.sends > 1:
            self.w.withdraw(ident, outgoing.payload)       # a copy not yet left: no air time
        if pending is not None and outgoing is not None and outgoing.sends == 1:
            self.rtt[ident].sample(self.w.clock.now() - outgoing.first_sent)   # Karn
        if pending is not None and not pending.token.done():
            pending.token.set_result(resp)

    def expire(self) -> None:
        now = self.w.clock.now()
        for (ident, seq), outgoing in list(self.outgoing.items()):
            rtt = self.rtt[ident]
            pending = self.calls.get(ident, seq)
            if not copy_due(self.w, ident, outgoing.payload, outgoing, now, rtt.rto,
                            None if pending is None else pending.deadline):
                continue
            rtt.backoff()
            outgoing.sends += 1
            outgoing.next_send = now + rtt.rto
            self.counters[ident].request_resends += 1
            # same seq: served once there; its age item is the call's (wire-format 15.6)
            if self.w.send(ident, outgoing.payload, published=outgoing.first_sent):
                self.w.expect(query(3, ident, seq), ident, outgoing.payload,
                              echo=pending is not None and self.w.urgent(pending.deadline))
        self._ask(now)
        for pending in self.calls.expire():
            self.outgoing.pop((pending.service_id, pending.seq), None)
            codec = self.called[pending.service_id]
            if pending.service_id in self.rtt:       # never toward an rmw_desert server
                self.asking[(pending.service_id, pending.seq)] = Asking(pending.started, now)
            self.counters[pending.service_id].timeouts += 1
            self.w.throttle.report(f"timeout{pending.service_id}",
                                   f"{codec.name}: call seq {pending.seq} got no response within "
                                   f"{codec.timeout:g} s: failed"
                                   + ("" if self.w.options.timeout_reply == TIMEOUT_REPLY_DEFAULT
                                      else " (no response is sent to the caller)"), expected=True)
            if not pending.token.done():
                pending.token.set_result(None)


    def _ask(self, now: float) -> None:
        """Ask about timed-out calls (outcomes.py) until the server side says, ASKS times."""
        for (ident, seq), asked in list(self.asking.items()):
            if asked.next_ask > now:
                continue
            codec = self.called[ident]
            if asked.asks >= ASKS:
                del self.asking[(ident, seq)]
                self.counters[ident].outcome_unknown += 1
                self.w.throttle.report(f"unknownoutcome{ident}", f"{codec.name}: call seq {seq} "
                                       "timed out and the server side did not say whether it ran "
                                       "(counted outcome_unknown)", expected=True)
                continue
            asked.asks += 1
            asked.next_ask = now + self.rtt[ident].rto
            self.counters[ident].outcome_queries += 1
            self.w.send(ident, query(2, ident, seq))


def service_status(standins: StandIns, servers: Servers, channels: dict[int, dict],
                   unavailable: dict[str, str]) -> dict[str, dict]:
    """The `services` section of ~/status."""
    services = {}
    call_stats = standins.calls.stats()
    for codec, serving in ([(c, False) for c in standins.codecs]
                           + [(c, True) for c in servers.codecs]):
        counters = (servers if serving else standins).counters
        entry = {"id": codec.id, "type": codec.type_name,
                 "role": "server" if serving else "client",
                 **asdict(counters[codec.id]), "link": channels.get(codec.id, {})}
        if not serving:
            entry["calls"] = call_stats.get(codec.id, {})
            lat = sorted(standins.calls.stats_of(codec.id).latencies)
            entry["latencies"] = [round(x, 4) for x in lat[-200:]]
        if codec.name in unavailable:
            entry["unavailable"] = unavailable[codec.name]
        services[codec.name] = entry
    return services


def allow_no_response(srv: Any, gone: Callable[[], None]) -> None:
    """Let a service callback return None to mean: send no response for this request, and
    let a response come after the service was destroyed (a stand-in withdrawn by the loop
    guard while its call waited for the link): it cannot reach its caller, so `gone()` is
    told (a counted drop) and it goes nowhere.

    rclpy's executor always calls `srv.send_response(result, header)` after the callback;
    with None it would raise TypeError, and on a destroyed service InvalidHandle, and stop
    the executor. An instance attribute shadows the method for this one service object only.
    """
    original = srv.send_response

    def send_response(response: Any, header: Any) -> None:
        if response is None:
            return
        try:
            original(response, header)
        except InvalidHandle:
            gone()
    srv.send_response = send_response
