"""The bridge node: one side of the manifest, one link to that side's DESERT node.

The node only wires parts to rclpy and the link; each part reads on its own:

- `topics.TopicBridge`: subscriptions that send, publishers of what arrives, echo guard;
- `services.StandIns` / `service_servers.Servers`: bridged service calls, both sides;
- `actions.ActionStandIns` (what comes back: `action_answers.GoalAnswers`) /
  `action_servers.ActionServers`: bridged actions, both sides;
- `discovery.RmwDiscovery`: rmw_desert beacons, when an entry is in profile rmw_desert;
- `status.StatusReporter`: ~/status, the stats file, drop log lines;
- `diagnostics.Watching`: /diagnostics (OK/WARN/ERROR per bridge and entry) and, with
  --record, the recording (`recorder.BridgeRecorder`: packets, messages, status in MCAP);
- `dispatch.Dispatcher`: each received payload's header read once, routed by (kind, id).

Threads. Everything here runs on the executor's thread except `_on_link_payload`, which
the link calls from its own thread; it only puts the payload in the `Inbox` and triggers
a guard condition, whose callback (on the executor) dispatches. Futures of bridged calls
are completed on the executor thread too, so pending service tasks are resumed without
any cross-thread wake-up.
"""
from __future__ import annotations

import json
import random
from dataclasses import asdict
from typing import Any, Callable

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup

from uwgen.runtime.delivery import ledger
from uwgen.bridge.action_servers import ActionServers
from uwgen.bridge.actions import ActionStandIns, action_status
from uwgen.bridge.copies import own_turns
from uwgen.bridge.counters import BridgeCounters
from uwgen.bridge.diagnostics import Watching
from uwgen.bridge.dispatch import Dispatcher
from uwgen.bridge.inbox import Inbox
from uwgen.bridge.medium import link_mac, mac_round_trip, warn_deadlines
from uwgen.bridge.plan import BridgeOptions, BridgePlan, PlanError
from uwgen.bridge.schema import SCHEMA_TICK, attach_schema, logger_say
from uwgen.bridge.recorder import recorder_for
from uwgen.bridge.reliability import farewell, link_ledger, reliability_for, wire_commands
from uwgen.bridge.rosnode import WholeNode
from uwgen.bridge.security import guard_for, link_security
from uwgen.bridge.service_servers import Servers
from uwgen.bridge.services import StandIns, service_status
from uwgen.bridge.status import StatusReporter, channel_stats, link_stats_of
from uwgen.bridge.topics import BRIDGE_NODE_PREFIX, TopicBridge
from uwgen.bridge.wiring import Wiring, qos_profile
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.runtime.link.mac import mac_for
from uwgen.runtime.link.hooks import join_hooks

__all__ = ["BridgeNode", "BRIDGE_NODE_PREFIX", "default_link_factory", "node_name_for",
           "qos_profile"]

EXPIRY_TICK = 0.05       # seconds between checks of call deadlines
GRAPH_TICK = 1.0         # seconds between checks for other bridges in this ROS graph
DRAIN_BATCH = 256        # payloads handled per guard-condition callback
LINK_TICK = 0.25         # seconds between checks for a reconnected link (discovery only)

LinkFactory = Callable[..., Any]


def default_link_factory(**kwargs: Any) -> Any:
    from uwgen.runtime.link.link import Link  # imported late: owned by the runtime
    return Link(**kwargs)


def node_name_for(plan: BridgePlan) -> str:
    return f"{BRIDGE_NODE_PREFIX}{plan.network}_{plan.side}".replace("-", "_")


class BridgeNode(WholeNode):
    """Carries one side's manifest topics, services and actions over its DESERT link."""

    def __init__(self, plan: BridgePlan, options: BridgeOptions | None = None, *,
                 link_factory: LinkFactory = default_link_factory, clock: Clock = SYSTEM_CLOCK,
                 context: Any = None, node_name: str | None = None,
                 rng: random.Random | None = None, start_link: bool = True,
                 flush_timeout: float | None = None):
        super().__init__(node_name or node_name_for(plan), context=context)
        self.plan = plan
        self.options = self._declare_parameters(options or plan.defaults)
        self._closed = False
        main_group = MutuallyExclusiveCallbackGroup()
        link_cfg = self.options.link
        self.mac = mac_for(plan.mac, plan.side, plan.side_ids, link_cfg, plan.wire_format)  # medium.py
        self.wiring = w = Wiring(node=self, send=self._send, clock=clock, options=self.options,
                                 log=self.get_logger(), main_group=main_group,
                                 service_group=ReentrantCallbackGroup(),
                                 round_trip=mac_round_trip(plan, link_cfg), turn_gap=self.mac.turn_gap(),
                                 measured_round=self.mac.round, next_turn=self.mac.next_turn)
        self._log = w.log
        w.recorder = recorder_for(plan, self.options, w.wall)   # None without --record
        self.counters = BridgeCounters()
        self.unavailable = w.unavailable                 # entry name -> why it is not bridged
        self.service_counters: dict = {}
        self.topics = TopicBridge(w, plan.outgoing_topics, plan.incoming_topics)
        self.standins = StandIns(w, plan.called_services, self.service_counters, rng=rng)
        self.servers = Servers(w, plan.served_services, self.service_counters)
        self.action_counters: dict = {}
        self.action_standins = ActionStandIns(w, plan.offered_actions, self.action_counters,
                                              rng=rng, handles=plan.action_handles)
        self.action_servers = ActionServers(w, plan.served_actions, self.action_counters)
        names = plan.entry_names()
        if names and all(name in self.unavailable for name in names):
            if w.recorder is not None:
                w.recorder.close()
            raise PlanError(f"nothing to bridge on side {plan.side}: rclpy has no type support "
                            f"here for any of its entries ({', '.join(names)})")

        self._wake = self.create_guard_condition(self._drain_inbox, callback_group=main_group)
        self.inbox = Inbox(self._wake.trigger)
        self.guard = guard_for(plan, self.options, clock)   # None unless the manifest protects ids
        security_kw, seal_hooks = link_security(self.guard)
        # Acks, re-sends of reliable topics, delivery once, stale commands (wire format 2 only;
        # docs/seams.md section 5), joined with the per-packet seal's hooks (one tag per packet)
        # when the link is secured.
        security_kw.update(link_mac(self.mac))
        self.reliability = reliability_for(plan, link_cfg, w.wall, other_overhead=(
            seal_hooks.overhead if seal_hooks is not None else 0) + self.mac.overhead,
            turn_gap=self.mac.turn_gap(), settled_by=self.mac.settled_by,
            unheard=self.mac.unheard, own_span=self.mac.own_span(), twice=self.mac.reports_twice())
        reliability_hooks = self.reliability.hooks() if self.reliability is not None else None
        if self.reliability is not None and hasattr(self.guard, "use_offsets"):
            # the seal reads T with each peer's measured clock offset; reliability judges
            # every command's own max age (docs/security.md, "Clocks")
            self.guard.use_offsets(self.reliability.offsets.of)
        if reliability_hooks is not None or seal_hooks is not None:
            security_kw["hooks"] = join_hooks(reliability_hooks, seal_hooks)
        self.link = link_factory(host=self.options.host, port=self.options.port, config=link_cfg,
                                 on_payload=self._on_link_payload, fragment_id=plan.fragment_id,
                                 clock=clock, name=plan.side, **plan.link_options(), **security_kw)
        for key, policy, name, whole in plan.channels():
            self.link.add_channel(key, policy, name, whole=whole)
        # commands' copies (copies.py): what waits in the link's queues, taking one back
        scheduler = getattr(self.link, "scheduler", None)
        if hasattr(scheduler, "waiting"):
            w.waiting, w.withdraw = scheduler.waiting, scheduler.withdraw
            w.turns = own_turns(self.mac)
        if self.reliability is not None:     # fates.py: each side repairs its own leg
            wire_commands(w, self.reliability)
        self.rmw_discovery = None   # RmwDiscovery when any entry is rmw_desert
        if plan.uses_rmw_desert:
            from uwgen.bridge.discovery import RmwDiscovery
            self.rmw_discovery = RmwDiscovery(w, plan, self.link, flush_timeout)
            self.create_timer(LINK_TICK, self.rmw_discovery.check_link, callback_group=main_group)
        self.schema = attach_schema(plan, self.link, clock, link_cfg, logger_say(self._log))
        warn_deadlines(self._log, plan, link_cfg)
        if self.schema is not None:   # SchemaGuard: fingerprints announced, mismatches refused
            self.create_timer(SCHEMA_TICK, self.schema.tick, callback_group=main_group)

        self.dispatcher = Dispatcher(self.counters)
        for part in (self.topics, self.standins, self.servers, self.action_standins,
                     self.action_servers, self.rmw_discovery, self.schema):
            if part is not None:
                part.register(self.dispatcher)
        for entry in plan.overheard:
            self.dispatcher.overhears(entry.id)

        self.reporter = StatusReporter(w, plan.network, plan.side)
        self.watching = Watching(self, w, plan, self.status)   # /diagnostics, the recording
        self.create_timer(EXPIRY_TICK, self._expire, callback_group=main_group)
        self.create_timer(GRAPH_TICK, self._check_graph, callback_group=main_group)
        if self.options.status_period > 0:
            self.create_timer(self.options.status_period, self.publish_status,
                              callback_group=main_group)
        self._log.info(f"{plan.describe()}; DESERT {self.options.host}:{self.options.port}, "
                       f"{link_cfg.max_read_length} B every {link_cfg.period} s")
        if self.unavailable:
            self._log.warning(f"not bridged (no rclpy type support here): {', '.join(sorted(self.unavailable))}")
        if start_link:
            self.start()

    def start(self) -> None:
        """Start the link (and discovery: request and beacons wait in the link's queues
        until it connects). Called by the constructor unless `start_link=False`."""
        if self.discovery is not None:
            self.discovery.start()
        if self.schema is not None:
            self.schema.start()      # queued ahead of data until the link connects
        self.link.start()

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
                                 **opts.unparameterised())

    # -- the parts' state, under the names the node has always had ------------------------

    @property
    def discovery(self) -> Any:
        """The DiscoveryAgent when any entry is rmw_desert, else None."""
        return self.rmw_discovery.agent if self.rmw_discovery is not None else None

    @property
    def topic_counters(self) -> dict:
        return self.topics.counters

    @property
    def echo_hazards(self) -> dict[str, str]:
        return self.topics.echo_hazards

    @property
    def _calls(self) -> Any:
        return self.standins.calls

    @property
    def _served(self) -> dict:
        return self.servers.served

    # -- link <-> executor -----------------------------------------------------------------

    def _send(self, ident: int, payload: bytes, published: float | None = None) -> bool:
        """Every payload the parts send goes through here to the link (`published`: on the
        link's clock, when known; see topics.publication_time)."""
        if published is None:
            return self.link.offer(ident, payload)
        return self.link.offer(ident, payload, published=published)

    def _on_link_payload(self, payload: bytes) -> None:
        """Called by the link, on the link's thread: hand over, touch nothing else but the
        command copies it answers (Wiring.take_back: before the turn it opens is built)."""
        if self.wiring.answered_by:
            self.wiring.take_back(bytes(payload))
        self.inbox.put(bytes(payload))

    def _drain_inbox(self) -> None:
        for payload in self.inbox.drain(DRAIN_BATCH):
            self.dispatch(payload)
        if len(self.inbox):
            self._wake.trigger()

    def dispatch(self, payload: bytes) -> None:
        """Route one complete payload from the link (executor thread)."""
        self.dispatcher.dispatch(payload)

    def _expire(self) -> None:
        self.wiring.throttle.tick()
        self.standins.expire()
        self.servers.expire()
        self.action_standins.expire()
        self.action_servers.expire()

    def _check_graph(self) -> None:
        self.topics.check_graph()
        self.wiring.loops.check_graph()

    # -- status ----------------------------------------------------------------------------

    def status(self) -> dict:
        """Everything the bridge and its link counted, as a JSON-able dict."""
        link_stats = link_stats_of(self.link)
        link_stats.get("reliability", {})["command_fates"] = self.wiring.fates.stats()
        channels = channel_stats(link_stats)
        for key, row in link_ledger(link_stats).items():   # what became of each copy sent
            channels.setdefault(key, {})["on_link"] = row
        self.counters.inbox_overflow = self.inbox.overflow
        return self.reporter.snapshot(
            link_stats, discovery=self.discovery_status(),
            schema=self.schema.stats() if self.schema is not None else None,
            topics=self.topics.status(channels, ledger.lost_on_link(link_stats)),
            services=service_status(self.standins, self.servers, channels, self.unavailable),
            actions=action_status(self.action_standins, self.action_servers, channels,
                                  self.unavailable),
            bridge=asdict(self.counters), echo_hazards={**self.echo_hazards, **self.wiring.loops.hazards},
            security=self.guard.stats() if self.guard is not None else None)

    def discovery_status(self) -> dict | None:
        """What this bridge announces to rmw_desert nodes and the remote graph it heard
        (None when no entry is in profile rmw_desert)."""
        return self.rmw_discovery.status() if self.rmw_discovery is not None else None

    def publish_status(self) -> dict:
        return self.watching.record(self.reporter.publish(self.status()))

    # -- shutdown --------------------------------------------------------------------------

    def close(self) -> dict:
        """Stop the link, write the final status, release ROS entities. Idempotent."""
        if self._closed:
            return {}
        self._closed = True
        if self.rmw_discovery is not None:
            self.rmw_discovery.stop()      # disconnect beacons, while the link still runs
        farewell(self.reliability, self.link, self.options.link.period)
        try:
            self.link.stop()
        except Exception as exc:
            self._log.warning(f"link did not stop cleanly: {exc}")
        if self.guard is not None:
            self.guard.close()                 # last drop summary; frees the side lock
        self.inbox.close()
        status = self.status()
        self.reporter.write(json.dumps(status, sort_keys=True, default=str))
        self.reporter.final_report(status)     # drops and errors not yet in a log line
        self.watching.close(status)
        self.wiring.throttle.flush()
        if self.context.ok():
            self.destroy_node()   # raises only on a bug: let it be seen
        else:
            try:
                self.destroy_node()
            except Exception as exc:  # rclpy after its context was shut down
                self._log.debug(f"destroy_node after shutdown: {exc}")
        return status

    def _flush_discovery(self) -> bool:
        """Wait (bounded) until the disconnect beacons have left; see RmwDiscovery.flush."""
        return self.rmw_discovery.flush() if self.rmw_discovery is not None else True
