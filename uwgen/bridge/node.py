"""The bridge node: one side of the manifest, one link to that side's DESERT node.

Threads. Everything here runs on the executor's thread except `_on_link_payload`, which
the link calls from its own thread; it only puts the payload in the `Inbox` and triggers
a guard condition, whose callback (on the executor) decodes and dispatches. Futures of
bridged calls are completed on the executor thread too, so pending service tasks are
resumed without any cross-thread wake-up.

Loops. A topic is outgoing (subscribed) on its publishing side only and incoming
(published) everywhere else, so no bridge holds both a subscription and a publisher of
one topic and none can take its own publication (rclpy's MessageInfo carries no
publisher gid in Jazzy, so a per-message filter is not possible). The remaining hazard is
two bridges of the same network sharing one ROS graph (same ROS_DOMAIN_ID): the
receiving bridge's publications would reach the sending bridge's subscription and go
back over the link. The bridge watches its outgoing topics for publishers that belong to
another uwgen bridge node and, while one exists, drops (and counts as `echo_guard`) what
it takes on that topic, with one error in the log. Run each side in its own domain.

rmw_desert peers (wire-format.md 6 and 6.1). When any manifest entry is in profile
`rmw_desert`, the bridge also runs `uwgen.interop.discovery.DiscoveryAgent` on link keys
1 and 2: it asks for remote beacons and announces its own at start and again whenever its
link reconnects (the far side may have restarted), answers every discovery request with
all its beacons, keeps what it hears in a RemoteGraph (in ~/status under `discovery`; the
graph logs one line per change) and withdraws its entities with disconnect beacons at
close, before the link stops. Calls toward an rmw_desert-profile service use seqs 1..999;
an rmw_desert server may answer only the latest of several outstanding requests, and the
older calls then time out at their deadline like any unanswered call (counted).

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

import json
import os
import random
import threading
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future

from uwgen.bridge.calls import RMW_DESERT_SEQ_RANGE, CallTable, CallTableFull
from uwgen.bridge.counters import BridgeCounters, DropReporter, ServiceCounters, TopicCounters
from uwgen.bridge.inbox import Inbox
from uwgen.bridge.plan import (TIMEOUT_REPLY_DEFAULT, BridgeOptions, BridgePlan, PlanError,
                               is_rmw_desert)
from uwgen.bridge.security import guard_for
from uwgen.interop.beacons import (DISCOVERY_ID, DISCOVERY_REQUEST_ID, DISCOVERY_REQUEST_TOPIC,
                                   DISCOVERY_TOPIC, BeaconError)
from uwgen.manifest.model import Qos
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.codec import KIND_REQUEST, KIND_RESPONSE, KIND_TOPIC, DecodeError, peek_header

BRIDGE_NODE_PREFIX = "uwgen_bridge_"
EXPIRY_TICK = 0.05       # seconds between checks of call deadlines
GRAPH_TICK = 1.0         # seconds between checks for other bridges in this ROS graph
DRAIN_BATCH = 256        # payloads handled per guard-condition callback
LINK_TICK = 0.25         # seconds between checks for a reconnected link (discovery only)
FLUSH_POLL = 0.01        # seconds between looks at the link while disconnect beacons leave

LinkFactory = Callable[..., Any]


def qos_profile(qos: Qos) -> QoSProfile:
    """The manifest's QoS as an rclpy profile (keep-last history of `depth`)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=max(1, int(qos.depth)),
        reliability=(ReliabilityPolicy.BEST_EFFORT if qos.reliability == "best_effort"
                     else ReliabilityPolicy.RELIABLE),
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if qos.durability == "transient_local"
                    else DurabilityPolicy.VOLATILE))


def default_link_factory(**kwargs: Any) -> Any:
    from uwgen.runtime.link import Link  # imported late: owned by the runtime
    return Link(**kwargs)


def node_name_for(plan: BridgePlan) -> str:
    return f"{BRIDGE_NODE_PREFIX}{plan.network}_{plan.side}".replace("-", "_")


class BridgeNode(Node):
    """Carries one side's manifest topics and services over its DESERT link."""

    def __init__(self, plan: BridgePlan, options: BridgeOptions | None = None, *,
                 link_factory: LinkFactory = default_link_factory, clock: Clock = SYSTEM_CLOCK,
                 context: Any = None, node_name: str | None = None,
                 rng: random.Random | None = None, start_link: bool = True,
                 flush_timeout: float | None = None):
        super().__init__(node_name or node_name_for(plan), context=context)
        self.plan = plan
        self.options = self._declare_parameters(options or plan.defaults)
        self._uwclock = clock
        self._log = self.get_logger()
        self._main_group = MutuallyExclusiveCallbackGroup()
        self._service_group = ReentrantCallbackGroup()  # stand-in calls wait on futures
        self.counters = BridgeCounters()
        self.topic_counters: dict[int, TopicCounters] = {}
        self.service_counters: dict[int, ServiceCounters] = {}
        self.unavailable: dict[str, str] = {}          # entry name -> why it is not bridged
        self.echo_hazards: dict[str, str] = {}         # outgoing topic -> foreign bridge node
        self._echo_dropped: dict[int, int] = {}
        self._publisher_counts: dict[str, int] = {}
        self._drops = DropReporter()
        self._said: set[str] = set()
        self._calls = CallTable(clock, rng=rng)
        self._serving: dict[int, dict[int, tuple[Future, float]]] = {}
        self._closed = False
        self.discovery: Any = None          # DiscoveryAgent when any entry is rmw_desert
        self._link_connects = 0
        self._flush_timeout = 0.0

        self._wake = self.create_guard_condition(self._drain_inbox, callback_group=self._main_group)
        self.inbox = Inbox(self._wake.trigger)

        self._incoming: dict[int, tuple[Any, Any]] = {}   # id -> (codec, publisher)
        self._outgoing: dict[int, Any] = {}               # id -> codec
        self._called: dict[int, Any] = {}                 # id -> codec (stand-in service here)
        self._served: dict[int, tuple[Any, Any]] = {}     # id -> (codec, client)
        # Not `_subscriptions`: that is rclpy Node's own list, which destroy_node() empties.
        self._bridge_subscriptions: list[Any] = []
        self._standins: list[Any] = []
        self._setup_topics()
        self._setup_services()

        link_cfg = self.options.link
        self.guard = guard_for(plan, self.options, clock)   # None unless the manifest protects ids
        self.link = link_factory(host=self.options.host, port=self.options.port, config=link_cfg,
                                 on_payload=self._on_link_payload, fragment_id=plan.fragment_id,
                                 clock=clock, name=plan.side,
                                 **({"guard": self.guard} if self.guard is not None else {}))
        for key, policy, name in plan.channels():
            self.link.add_channel(key, policy, name)
        self.discovery = self._setup_discovery(flush_timeout)

        self._status_pub = self.create_publisher(_string_class(), "~/status", 10)
        self.create_timer(EXPIRY_TICK, self._expire, callback_group=self._main_group)
        self.create_timer(GRAPH_TICK, self._check_graph, callback_group=self._main_group)
        if self.options.status_period > 0:
            self.create_timer(self.options.status_period, self.publish_status,
                              callback_group=self._main_group)
        self._log.info(f"{plan.describe()}; DESERT {self.options.host}:{self.options.port}, "
                       f"{link_cfg.max_read_length} B every {link_cfg.period} s")
        if start_link:
            self.start()

    def start(self) -> None:
        """Start the link (and discovery: request and beacons wait in the link's queues
        until it connects). Called by the constructor unless `start_link=False`."""
        if self.discovery is not None:
            self.discovery.start()
        self.link.start()

    # -- set-up --------------------------------------------------------------------------

    def _declare_parameters(self, opts: BridgeOptions) -> BridgeOptions:
        """ROS parameters (e.g. `--ros-args -p desert_port:=4001`) override the options."""
        p = {
            "desert_host": opts.host, "desert_port": opts.port,
            "max_read_length": opts.link.max_read_length, "period": float(opts.link.period),
            "status_period": float(opts.status_period),
            "service_timeout_reply": opts.timeout_reply,
        }
        for name, value in p.items():
            self.declare_parameter(name, value)
        get = lambda n: self.get_parameter(n).value  # noqa: E731
        return self.plan.options(host=get("desert_host"), port=get("desert_port"),
                                 max_read_length=get("max_read_length"), period=get("period"),
                                 status_period=float(get("status_period")),
                                 timeout_reply=get("service_timeout_reply"),
                                 stats_file=opts.stats_file, key_file=opts.key_file,
                                 security_state=opts.security_state)

    def _ros_class(self, codec: Any, service: bool = False) -> Any | None:
        """The rclpy class of an entry, or None (logged, reported) when rclpy has no type
        support for it here (e.g. the codec fell back to its generated plain class)."""
        from rclpy.type_support import check_for_type_support
        try:
            cls = codec.ros_class()
            check_for_type_support(cls)
            if service and not hasattr(cls, "Request"):
                raise TypeError(f"{cls!r} is not a service type")
        except Exception as exc:  # ImportError, AttributeError, NoTypeSupportImportedException
            why = f"{type(exc).__name__}: {exc}".split(" This might be a ROS 1")[0]
            self.unavailable[codec.name] = why
            self._log.error(f"{codec.name} ({codec.type_name}) is not bridged: rclpy has no type "
                            f"support for it here ({why})")
            return None
        return cls

    def _setup_topics(self) -> None:
        for codec in self.plan.outgoing_topics:
            self.topic_counters[codec.id] = TopicCounters()
            cls = self._ros_class(codec)
            if cls is None:
                continue
            self._outgoing[codec.id] = codec
            self._bridge_subscriptions.append(self.create_subscription(
                cls, codec.name, self._taker(codec), qos_profile(codec.qos),
                callback_group=self._main_group))
        for codec in self.plan.incoming_topics:
            self.topic_counters[codec.id] = TopicCounters()
            cls = self._ros_class(codec)
            if cls is None:
                continue
            pub = self.create_publisher(cls, codec.name, qos_profile(codec.qos))
            self._incoming[codec.id] = (codec, pub)

    def _setup_services(self) -> None:
        for codec in self.plan.called_services:
            self.service_counters[codec.id] = ServiceCounters()
            cls = self._ros_class(codec, service=True)
            if cls is None:
                continue
            srv = self.create_service(cls, codec.name, self._standin(codec),
                                      callback_group=self._service_group)
            _allow_no_response(srv)
            self._standins.append(srv)
            self._called[codec.id] = codec
            if is_rmw_desert(codec):
                self._calls.set_seq_range(codec.id, *RMW_DESERT_SEQ_RANGE)
        for codec in self.plan.served_services:
            self.service_counters[codec.id] = ServiceCounters()
            cls = self._ros_class(codec, service=True)
            if cls is None:
                continue
            client = self.create_client(cls, codec.name, callback_group=self._main_group)
            self._served[codec.id] = (codec, client)
            self._serving[codec.id] = {}

    def _setup_discovery(self, flush_timeout: float | None) -> Any:
        """The DiscoveryAgent on link keys 1 and 2, or None when no entry is rmw_desert."""
        if not self.plan.uses_rmw_desert:
            return None
        from uwgen.interop.discovery import DiscoveryAgent, beacons_for, discovery_policies
        plan = self.plan
        names = {DISCOVERY_ID: DISCOVERY_TOPIC, DISCOVERY_REQUEST_ID: DISCOVERY_REQUEST_TOPIC}
        taken = sorted({e.id for e in (*plan.topics, *plan.services)} & names.keys())
        if taken:
            raise PlanError(f"ids {taken} are rmw_desert's discovery topics but the manifest "
                            f"gives them to its own entries")
        # Entries rclpy cannot carry here are not bridged, so not announced either: an
        # rmw_desert client would otherwise wait for a server that never answers.
        bridged = lambda entries: [e for e in entries if e.name not in self.unavailable]  # noqa: E731
        try:
            beacons = beacons_for(plan.network, plan.side, bridged(plan.topics),
                                  bridged(plan.services))
        except BeaconError as exc:
            raise PlanError(f"cannot announce this side to rmw_desert nodes: {exc}") from None
        for key, policy in discovery_policies(len(beacons)).items():
            self.link.add_channel(key, policy, names.get(key))
        agent = DiscoveryAgent(beacons, send=self.link.offer, clock=self._uwclock)
        self._flush_timeout = (self._default_flush_timeout(beacons)
                               if flush_timeout is None else float(flush_timeout))
        self.create_timer(LINK_TICK, self._check_link, callback_group=self._main_group)
        self._log.info(f"rmw_desert discovery on: announcing {len(beacons)} entities as node "
                       f"{beacons[0].node_name if beacons else '-'} (link keys 1 and 2)")
        return agent

    def _default_flush_timeout(self, beacons: list[Any]) -> float:
        """Wall-clock bound on waiting for the disconnect beacons to leave at close: the
        link's time for what the discovery queue can hold then (two rounds of beacons,
        then the disconnect beacons; 4 bytes of framing each), plus two periods; at most
        10 s. Only a bound: close() goes on as soon as the queue is empty."""
        from uwgen.interop.beacons import encode_beacon
        cfg = self.options.link
        size = sum(2 * (len(encode_beacon(b)) + 4) + len(encode_beacon(b.gone())) + 4
                   for b in beacons)
        writes = -(-size // max(1, cfg.max_read_length))
        return min(10.0, (writes + 2) * cfg.period * 1.1)

    def _check_link(self) -> None:
        """Announce again (with a request) when the link has reconnected since last look.

        The first connection only carries what start() queued; any later one may face a
        restarted far side that has forgotten us, as rmw_desert nodes ask only at start-up.
        """
        try:
            connects = _connects(self.link.stats())
        except Exception:  # the link is shutting down
            return
        if connects is None:
            return
        if connects > max(self._link_connects, 1) and self.discovery is not None:
            self._log.info("link reconnected: asking remote nodes for their beacons and "
                           "announcing ours again")
            self.discovery.announce(request=True)
        self._link_connects = max(self._link_connects, connects)

    # -- outgoing topics -------------------------------------------------------------------

    def _taker(self, codec: Any) -> Callable[[Any], None]:
        counters = self.topic_counters[codec.id]

        def take(msg: Any) -> None:
            counters.taken += 1
            if self.echo_hazards and self._echo_blocked(codec):
                return
            try:
                payload = codec.encode(msg)
            except ValueError as exc:  # EncodeError: bounds, ranges, too long for the profile
                counters.encode_errors += 1
                self._say_once(f"enc{codec.id}{type(exc).__name__}",
                               f"{codec.name}: message not sent, cannot encode: {exc}")
                return
            if self.link.offer(codec.id, payload):
                counters.offered += 1
            else:
                counters.refused += 1
        return take

    def _echo_blocked(self, codec: Any) -> bool:
        if codec.name in self.echo_hazards:
            self._echo_dropped[codec.id] = self._echo_dropped.get(codec.id, 0) + 1
            return True
        return False

    # -- link -> executor ------------------------------------------------------------------

    def _on_link_payload(self, payload: bytes) -> None:
        """Called by the link, on the link's thread: hand over, touch nothing else."""
        self.inbox.put(bytes(payload))

    def _drain_inbox(self) -> None:
        for payload in self.inbox.drain(DRAIN_BATCH):
            self.dispatch(payload)
        if len(self.inbox):
            self._wake.trigger()

    def dispatch(self, payload: bytes) -> None:
        """Route one complete payload from the link (executor thread)."""
        if self.discovery is not None and self.discovery.handle(payload):
            return  # kind 0 on id 1 or 2: a beacon (to the graph) or a discovery request
        try:
            kind, ident = peek_header(payload)
        except DecodeError:
            self.counters.bad_header += 1
            return
        if kind == KIND_TOPIC and ident in self._incoming:
            self._publish_incoming(ident, payload)
        elif kind == KIND_REQUEST and ident in self._served:
            self._serve_request(ident, payload)
        elif kind == KIND_RESPONSE and ident in self._called:
            self._complete_call(ident, payload)
        elif ident in self._outgoing or ident in self._served or ident in self._called:
            mine = ((kind == KIND_TOPIC and ident in self._outgoing)
                    or (kind == KIND_REQUEST and ident in self._called)
                    or (kind == KIND_RESPONSE and ident in self._served))
            if mine:
                self.counters.wrong_direction += 1
            else:
                self.counters.bad_kind += 1
        elif ident in self._incoming:
            self.counters.bad_kind += 1
        else:
            self.counters.unknown_id += 1

    def _publish_incoming(self, ident: int, payload: bytes) -> None:
        codec, pub = self._incoming[ident]
        counters = self.topic_counters[ident]
        counters.received += 1
        try:
            msg = codec.decode(payload)
        except ValueError as exc:  # DecodeError
            counters.decode_errors += 1
            self._say_once(f"dec{ident}", f"{codec.name}: payload dropped, does not decode: {exc}")
            return
        try:
            pub.publish(msg)
        except Exception as exc:  # a type mismatch between codec and rclpy class
            counters.publish_errors += 1
            self._say_once(f"pub{ident}", f"{codec.name}: cannot publish decoded message: {exc}")
            return
        counters.published += 1

    # -- services: calling side ------------------------------------------------------------

    def _standin(self, codec: Any) -> Callable:
        counters = self.service_counters[codec.id]

        async def call(request: Any, response: Any) -> Any:
            counters.local_calls += 1
            future = Future()
            try:
                pending = self._calls.begin(codec.id, codec.timeout, token=future)
            except CallTableFull as exc:
                counters.refused += 1
                self._log.error(f"{codec.name}: call refused: {exc}")
                return self._failed_reply(response)
            try:
                payload = codec.encode_request(pending.seq, request)
            except ValueError as exc:
                counters.encode_errors += 1
                self._calls.abandon(codec.id, pending.seq)
                self._log.error(f"{codec.name}: call failed, request cannot be encoded: {exc}")
                return self._failed_reply(response)
            if not self.link.offer(codec.id, payload):
                counters.refused += 1
                self._calls.abandon(codec.id, pending.seq)
                self._log.error(f"{codec.name}: call seq {pending.seq} failed: the link refused "
                                "the request (queue full or too large; see ~/status)")
                return self._failed_reply(response)
            result = await future
            if result is None:
                return self._failed_reply(response)
            counters.responses += 1
            return result
        return call

    def _failed_reply(self, response: Any) -> Any:
        # None: no response at all (see the module doc); the patched send_response skips it.
        return response if self.options.timeout_reply == TIMEOUT_REPLY_DEFAULT else None

    def _complete_call(self, ident: int, payload: bytes) -> None:
        codec = self._called[ident]
        try:
            seq, resp = codec.decode_response(payload)
        except ValueError as exc:
            self.service_counters[ident].decode_errors += 1
            self._say_once(f"dresp{ident}", f"{codec.name}: response dropped, does not decode: {exc}")
            return
        pending = self._calls.complete(ident, seq)
        if pending is not None and not pending.token.done():
            pending.token.set_result(resp)

    # -- services: serving side ------------------------------------------------------------

    def _serve_request(self, ident: int, payload: bytes) -> None:
        codec, client = self._served[ident]
        counters = self.service_counters[ident]
        try:
            seq, request = codec.decode_request(payload)
        except ValueError as exc:
            counters.decode_errors += 1
            self._say_once(f"dreq{ident}", f"{codec.name}: request dropped, does not decode: {exc}")
            return
        counters.requests += 1
        serving = self._serving[ident]
        if seq in serving:
            counters.duplicate_requests += 1
            return
        if not client.service_is_ready():
            counters.no_server += 1
            self._log.error(f"{codec.name}: request seq {seq} not served: no local server "
                            "is available (the caller will time out)")
            return
        future = client.call_async(request)
        serving[seq] = (future, self._uwclock.now() + codec.timeout)
        future.add_done_callback(lambda f: self._reply(ident, seq, f))

    def _reply(self, ident: int, seq: int, future: Future) -> None:
        codec, _ = self._served[ident]
        counters = self.service_counters[ident]
        entry = self._serving[ident].get(seq)
        if entry is None or entry[0] is not future:
            return  # already timed out
        del self._serving[ident][seq]
        if future.cancelled():
            return
        exc = future.exception()
        if exc is not None:
            counters.server_errors += 1
            self._log.error(f"{codec.name}: local call for seq {seq} failed: {exc}")
            return
        try:
            payload = codec.encode_response(seq, future.result())
        except ValueError as exc:
            counters.server_errors += 1
            self._log.error(f"{codec.name}: response for seq {seq} cannot be encoded: {exc}")
            return
        if self.link.offer(ident, payload):
            counters.replies += 1
        else:
            counters.reply_refused += 1
            self._log.error(f"{codec.name}: response for seq {seq} refused by the link")

    # -- timers ----------------------------------------------------------------------------

    def _expire(self) -> None:
        for pending in self._calls.expire():
            codec = self._called[pending.service_id]
            self.service_counters[pending.service_id].timeouts += 1
            self._log.error(f"{codec.name}: call seq {pending.seq} got no response within "
                            f"{codec.timeout:g} s: failed"
                            + ("" if self.options.timeout_reply == TIMEOUT_REPLY_DEFAULT
                               else " (no response is sent to the caller)"))
            if not pending.token.done():
                pending.token.set_result(None)
        now = self._uwclock.now()
        for ident, serving in self._serving.items():
            codec, client = self._served[ident]
            for seq, (future, deadline) in list(serving.items()):
                if deadline <= now:
                    del serving[seq]
                    client.remove_pending_request(future)
                    future.cancel()
                    self.service_counters[ident].server_timeouts += 1
                    self._log.error(f"{codec.name}: local server did not answer seq {seq} "
                                    f"within {codec.timeout:g} s")

    def _check_graph(self) -> None:
        """Find other uwgen bridges publishing our outgoing topics in this ROS graph."""
        for ident, codec in self._outgoing.items():
            try:
                infos = self.get_publishers_info_by_topic(codec.name)
            except Exception:  # the context is shutting down
                return
            foreign = sorted({i.node_name for i in infos
                              if i.node_name.startswith(BRIDGE_NODE_PREFIX)
                              and (i.node_name, i.node_namespace) != (self.get_name(),
                                                                       self.get_namespace())})
            if foreign and codec.name not in self.echo_hazards:
                self.echo_hazards[codec.name] = foreign[0]
                self._log.error(
                    f"{codec.name}: bridge node {foreign[0]} publishes this topic in the same ROS "
                    f"graph, so what it receives would be sent back over the link; not sending "
                    f"{codec.name} until it is gone (give each side its own ROS_DOMAIN_ID)")
            elif not foreign and codec.name in self.echo_hazards:
                del self.echo_hazards[codec.name]
                self._log.info(f"{codec.name}: no other bridge publishes it any more; sending again")

    # -- status ----------------------------------------------------------------------------

    def status(self) -> dict:
        """Everything the bridge and its link counted, as a JSON-able dict."""
        try:
            link_stats = self.link.stats()
        except Exception as exc:
            link_stats = {"error": str(exc)}
        channels = _channel_stats(link_stats)
        topics = {}
        for codec in (*self.plan.outgoing_topics, *self.plan.incoming_topics):
            out = codec.publisher == self.plan.side
            entry = {"id": codec.id, "type": codec.type_name,
                     "direction": "out" if out else "in", **asdict(self.topic_counters[codec.id])}
            if out:
                entry["echo_guard"] = self._echo_dropped.get(codec.id, 0)
                entry["link"] = channels.get(codec.id, {})
            if codec.name in self.unavailable:
                entry["unavailable"] = self.unavailable[codec.name]
            topics[codec.name] = entry
        services = {}
        call_stats = self._calls.stats()
        for codec in (*self.plan.called_services, *self.plan.served_services):
            serving = codec.server == self.plan.side
            entry = {"id": codec.id, "type": codec.type_name,
                     "role": "server" if serving else "client",
                     **asdict(self.service_counters[codec.id]),
                     "link": channels.get(codec.id, {})}
            if not serving:
                entry["calls"] = call_stats.get(codec.id, {})
                lat = sorted(self._calls.stats_of(codec.id).latencies)
                entry["latencies"] = [round(x, 4) for x in lat[-200:]]
            if codec.name in self.unavailable:
                entry["unavailable"] = self.unavailable[codec.name]
            services[codec.name] = entry
        self.counters.inbox_overflow = self.inbox.overflow
        return {"network": self.plan.network, "side": self.plan.side, "time": time.time(),
                "discovery": self.discovery_status(),
                "desert": {"host": self.options.host, "port": self.options.port,
                           "max_read_length": self.options.link.max_read_length,
                           "period": self.options.link.period},
                "topics": topics, "services": services,
                "bridge": asdict(self.counters), "echo_hazards": dict(self.echo_hazards),
                "link": link_stats, "security": link_stats.get("security")}

    def discovery_status(self) -> dict | None:
        """What this bridge announces to rmw_desert nodes and the remote graph it heard
        (None when no entry is in profile rmw_desert)."""
        agent = self.discovery
        if agent is None:
            return None
        return {
            "announced": [{"node": b.node_name, "entity": b.entity.name.lower(),
                           "topic": b.topic, "type": b.type_name} for b in agent.beacons],
            "counters": agent.stats(),
            "remote": agent.graph.as_dict()["entities"],
        }

    def publish_status(self) -> dict:
        status = self.status()
        self._report_drops(status)
        msg = _string_class()()
        msg.data = json.dumps(status, sort_keys=True, default=str)
        try:
            self._status_pub.publish(msg)
        except Exception:
            pass
        self._write_stats(msg.data)
        return status

    def _report_drops(self, status: dict) -> None:
        for name, entry in status["topics"].items():
            if entry.get("link", {}).get("superseded") and f"sup{name}" not in self._said:
                self._said.add(f"sup{name}")
                self._log.info(f"{name}: published faster than its link policy sends; older "
                               "messages are superseded by newer ones (counted in ~/status)")
            parts = self._drops.changes("topic", name, entry)
            parts += self._drops.changes("link", name, entry.get("link", {}))
            if parts:
                self._log.warning(f"{name}: dropped since last report: {', '.join(parts)}")
        for name, entry in status["services"].items():
            parts = self._drops.changes("service", name, {**entry, **entry.get("calls", {})})
            parts += self._drops.changes("link", name, entry.get("link", {}))
            if parts:
                self._log.warning(f"{name}: dropped since last report: {', '.join(parts)}")
        parts = self._drops.changes("bridge", "", status["bridge"])
        if parts:
            self._log.warning(f"payloads dropped since last report: {', '.join(parts)}")

    def _write_stats(self, text: str) -> None:
        path = self.options.stats_file
        if path is None:
            return
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(text)
            os.replace(tmp, path)
        except OSError as exc:
            self._say_once("statsfile", f"cannot write stats file {path}: {exc}")

    def _say_once(self, key: str, text: str) -> None:
        """Log the first occurrence of a kind of problem; later ones are counted only."""
        if key not in self._said:
            self._said.add(key)
            self._log.error(text + " (further ones are counted in ~/status)")

    # -- shutdown --------------------------------------------------------------------------

    def close(self) -> dict:
        """Stop the link, write the final status, release ROS entities. Idempotent."""
        if self._closed:
            return {}
        self._closed = True
        if self.discovery is not None:
            self.discovery.stop()          # disconnect beacons, while the link still runs
            if not self._flush_discovery():
                self._log.warning(f"disconnect beacons not all sent within "
                                  f"{self._flush_timeout:g} s; remote rmw_desert nodes may "
                                  "keep listing this bridge's entities")
        try:
            self.link.stop()
        except Exception as exc:
            self._log.warning(f"link did not stop cleanly: {exc}")
        if self.guard is not None:
            self.guard.close()                 # exact sequence numbers for the next start
        self.inbox.close()
        status = self.status()
        self._write_stats(json.dumps(status, sort_keys=True, default=str))
        if self.context.ok():
            self.destroy_node()   # raises only on a bug: let it be seen
        else:
            try:
                self.destroy_node()
            except Exception as exc:  # rclpy after its context was shut down
                self._log.debug(f"destroy_node after shutdown: {exc}")
        return status

    def _flush_discovery(self) -> bool:
        """Wait (wall clock, bounded by flush_timeout) until the link has written every
        queued beacon; True when it has, or when it is not connected (nothing can leave).

        Wall clock on purpose: shutdown must end whatever an injected clock does."""
        deadline = time.monotonic() + self._flush_timeout
        waiter = threading.Event()
        while True:
            try:
                stats = self.link.stats()
            except Exception:
                return False
            if not stats.get("connected"):
                return True
            queued = _channel_stats(stats).get(DISCOVERY_ID, {}).get("queued", 0)
            connection = getattr(self.link, "connection", None)
            cut = bool(getattr(getattr(connection, "outbox", None), "pending", False))
            if not queued and not cut:
                if connection is not None:
                    # The last write is in the socket; give DESERT one period to read it
                    # before the socket closes.
                    waiter.wait(min(self.options.link.period,
                                    max(0.0, deadline - time.monotonic())))
                return True
            if time.monotonic() >= deadline:
                return False
            waiter.wait(FLUSH_POLL)


def _allow_no_response(srv: Any) -> None:
    """Let a service callback return None to mean: send no response for this request.

    rclpy's executor always calls `srv.send_response(result, header)` after the callback;
    with None it would raise TypeError and stop the executor. An instance attribute shadows
    the method for this one service object only.
    """
    original = srv.send_response

    def send_response(response: Any, header: Any) -> None:
        if response is not None:
            original(response, header)
    srv.send_response = send_response


def _connects(link_stats: Any) -> int | None:
    """How many times the link has connected (None when its stats do not say)."""
    if not isinstance(link_stats, dict):
        return None
    value = (link_stats.get("connection") or {}).get("connects")
    return value if isinstance(value, int) else None


def _channel_stats(link_stats: Any) -> dict[int, dict]:
    """Per-channel counters from link.stats(), keyed by int id, whatever the key type."""
    if not isinstance(link_stats, dict):
        return {}
    chans = link_stats.get("channels", {})
    out: dict[int, dict] = {}
    if isinstance(chans, dict):
        for key, value in chans.items():
            try:
                out[int(key)] = value
            except (TypeError, ValueError):
                continue
    return out


def _string_class() -> Any:
    from std_msgs.msg import String
    return String

