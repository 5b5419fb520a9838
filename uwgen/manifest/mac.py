"""The manifest's `mac:` section (model.MacConfig), read with file:line:column errors.

    mac: {mode: none}                                    # the default: DESERT's MAC decides
    mac: {mode: tdma, frame: 1.0, guard: 0.25, slots: [surface, vehicle],
          max_packet_per_slot: 4, queue_size: 10, bitrate: 4800, range: 300}
    mac: {mode: tdma, frame: 4.5, guard: 0.2, slots: [surface, auv1, auv2],
          weights: {surface: 2}}                         # the surface's slot is twice as long
    mac: {mode: turns, leader: surface, packets: {surface: 4, vehicle: 3},
          bitrate: 4800, range: 300}

Refused here, at the offending node: an unknown side, a side given two slots (two slots of one
frame overlap in time for no one: DESERT's UW/TDMA gives each node exactly one; a side that
needs more of the frame gets a longer slot, `weights`), a side without a slot, a weight for a
side without a slot or outside 1..100, a guard that leaves no ON window in some side's slot,
and turn-taking on a wire format 1 link (no C part).
What only costs time (a guard shorter than a packet's air time plus the range, a deadline
shorter than a round trip under the MAC) is `uwgen analyze`'s warning (uwgen.analyze).
"""
from __future__ import annotations

from typing import Any

import yaml

from uwgen.manifest.model import MAC_MODES, MacConfig, Side
from uwgen.manifest.nodes import Reader

MAC_KEYS = ("mode", "bitrate", "range", "frame", "guard", "slots", "max_packet_per_slot",
            "queue_size", "weights", "leader", "packets")
TDMA_ONLY = ("frame", "guard", "slots", "max_packet_per_slot", "queue_size", "weights")
TURNS_ONLY = ("leader", "packets")
PACKET_HEADER = 4            # bytes DESERT adds to each packet on the air (pacing.PACKET_HEADER)


def air_time(nbytes: int, bitrate: float) -> float:
    """Seconds a packet of `nbytes` payload bytes is on the air."""
    return (nbytes + PACKET_HEADER) * 8 / bitrate


def read_mac(r: Reader, node: yaml.Node, sides: dict[str, Side]) -> MacConfig:
    fields = r.mapping(node, "mac", MAC_KEYS)
    mode = "none"
    if "mode" in fields:
        mode = r.choice(fields["mode"][1], "mac mode", MAC_MODES)
    for key in (*TDMA_ONLY, *TURNS_ONLY):
        owner = "tdma" if key in TDMA_ONLY else "turns"
        if key in fields and mode != owner:
            raise r.error(fields[key][0], f"mac key '{key}' belongs to mode {owner}, not {mode}")
    kw: dict[str, Any] = {"mode": mode}
    for key in ("bitrate", "range", "frame", "guard"):
        if key in fields:
            kw[key] = r.number(fields[key][1], f"mac {key}", positive=key != "guard")
    for key in ("max_packet_per_slot", "queue_size"):
        if key in fields:
            kw[key] = r.integer(fields[key][1], f"mac {key}", 1, 100_000)
    if mode == "tdma":
        kw["slots"] = _slots(r, fields, node, sides)
        kw["weights"] = _weights(r, fields, kw["slots"])
        config = MacConfig(**kw)
        _check_window(r, fields, node, config, sides)
        return config
    if mode == "turns":
        kw["leader"] = _leader(r, fields, sides)
        kw["packets"] = _packets(r, fields, sides)
    return MacConfig(**kw)


def _side(r: Reader, node: yaml.Node, what: str, sides: dict[str, Side]) -> str:
    name = r.string(node, what)
    if name not in sides:
        raise r.error(node, f"{what} '{name}' is not a declared side (sides: {', '.join(sides)})")
    return name


def _slots(r: Reader, fields: dict, owner: yaml.Node, sides: dict[str, Side]) -> tuple[str, ...]:
    if "slots" not in fields:
        return tuple(sides)
    node = fields["slots"][1]
    seen: dict[str, yaml.Node] = {}
    for item in r.sequence(node, "mac slots"):
        name = _side(r, item, "mac slot", sides)
        if name in seen:
            first = r.where(seen[name])
            raise r.error(item, f"side '{name}' has two slots (also at line {first.line}): its "
                          "slots would overlap the others'; DESERT's UW/TDMA gives a node one slot")
        seen[name] = item
    missing = [s for s in sides if s not in seen]
    if missing:
        raise r.error(node, f"mac slots leave side(s) {', '.join(missing)} without a slot: they "
                      "could never send")
    return tuple(seen)


def _weights(r: Reader, fields: dict, slots: tuple[str, ...]) -> tuple[tuple[str, int], ...]:
    if "weights" not in fields:
        return ()
    out = []
    for name, (key_node, value_node) in r.open_mapping(fields["weights"][1], "mac weights").items():
        if name not in slots:
            raise r.error(key_node, f"mac weights: '{name}' has no slot (slots: {', '.join(slots)})")
        weight = r.integer(value_node, f"mac weight of side '{name}'", 1, 100)
        if weight != 1:
            out.append((name, weight))
    return tuple(out)


def _check_window(r: Reader, fields: dict, owner: yaml.Node, config: MacConfig,
                  sides: dict[str, Side]) -> None:
    side = min(config.slots, key=config.slot_length)          # the shortest slot
    slot = config.slot_length(side)
    on = slot - config.guard
    at = fields.get("guard", fields.get("frame", (owner, owner)))[1]
    whose = (f"side {side}'s {slot:g} s slot (frame {config.frame:g} s, weight "
             f"{config.weight(side)} of {sum(config.slot_weights())})" if config.weights else
             f"a {slot:g} s slot (frame {config.frame:g} s / {len(config.slots)} slots)")
    if on <= 0:
        raise r.error(at, f"mac guard {config.guard:g} s leaves no time to send in {whose}")
    if on < 1e-3:
        raise r.error(at, f"mac guard {config.guard:g} s leaves a {on * 1000:.2f} ms window in "
                      f"{whose}: no packet can start in it reliably")


def _leader(r: Reader, fields: dict, sides: dict[str, Side]) -> str:
    if "leader" in fields:
        return _side(r, fields["leader"][1], "mac leader", sides)
    return next(iter(sides))


def _packets(r: Reader, fields: dict, sides: dict[str, Side]) -> tuple[tuple[str, int], ...]:
    if "packets" not in fields:
        return ()
    node = fields["packets"][1]
    if isinstance(node, yaml.ScalarNode):
        n = r.integer(node, "mac packets (per turn)", 1, 255)
        return tuple((s, n) for s in sides)
    out = []
    for name, (key_node, value_node) in r.open_mapping(node, "mac packets").items():
        if name not in sides:
            raise r.error(key_node, f"mac packets: '{name}' is not a declared side "
                          f"(sides: {', '.join(sides)})")
        out.append((name, r.integer(value_node, f"mac packets of side '{name}'", 1, 255)))
    return tuple(out)


def check_turns_wire(r: Reader, node: yaml.Node, config: MacConfig, uses_rmw_desert: bool) -> None:
    """Turn-taking needs the C part of the envelope (wire format 4): refused on a wire format 1
    network."""
    if config.mode == "turns" and uses_rmw_desert:
        raise r.error(node, "mac mode turns needs wire format 4 (its grants are C items), but an "
                      "entry in profile rmw_desert keeps this network on wire format 1: use "
                      "mode tdma or none")


def mac_from_text(text: str, sides: list[str] | dict, what: str = "--mac") -> MacConfig:
    """A `mac:` section given on a command line (a YAML flow mapping, as in the manifest:
    `{mode: tdma, frame: 1.0, guard: 0.35}`), checked as the manifest's; ManifestError
    located in `what`."""
    from pathlib import Path

    from uwgen import yamltext
    from uwgen.manifest.nodes import ManifestError

    try:
        node = yaml.compose(text, Loader=yamltext.Loader)
    except yaml.YAMLError as exc:
        raise ManifestError(None, f"{what}: not YAML: {exc}") from None
    if node is None:
        raise ManifestError(None, f"{what}: empty; expected e.g. {{mode: turns}}")
    names = {name: Side(name) for name in sides}
    return read_mac(Reader(Path(what)), node, names)


def round_trip(config: MacConfig, period: float, max_read_length: int,
               sides: list[str] | None = None) -> float:
    """Seconds a request and its answer take under the MAC at most, in the steady state, with
    no loss: what a deadline must leave room for (uwgen analyze warns, the bridge logs).
    One way: DESERT's period tick, its MAC's listen, the air time and the range; then the
    wait for a turn: a frame (tdma), a round of turns (turns)."""
    air = air_time(max_read_length, config.bitrate)
    one_way = period + air + config.delay
    if config.mode == "tdma":
        return config.frame + 2 * one_way
    if config.mode == "turns":
        interval = max(period * 1.05, air)
        names = sides or [config.leader]
        followers = [s for s in names if s != config.leader]
        cycle = config.turn_packets(config.leader) * interval + sum(
            config.turn_packets(s) * interval + 2 * (one_way + LISTEN) for s in followers)
        return cycle + 2 * one_way
    return 2 * (one_way + LISTEN)


LISTEN = 0.05     # s: DESERT's CSMA-ALOHA listen before a packet starts (runtime.link.mac.LISTEN)


def mac_of_file(path) -> MacConfig:
    """The `mac:` section of the manifest at `path`, checked against its side names only
    (no type is resolved): for the demo, which knows its manifest is otherwise valid."""
    from pathlib import Path

    from uwgen.manifest.nodes import compose
    path = Path(path)
    root = compose(path)
    r = Reader(path)
    if not isinstance(root, yaml.MappingNode):
        return MacConfig()
    top = {k.value: v for k, v in root.value}
    if "mac" not in top or not isinstance(top.get("sides"), yaml.MappingNode):
        return MacConfig()
    sides = {k.value: Side(k.value) for k, _ in top["sides"].value}
    if isinstance(top.get("fleet"), yaml.MappingNode):   # a fleet's vehicles have slots and turns too
        from uwgen.manifest.fleet import vehicle_names
        sides.update({v: Side(v) for v in vehicle_names(r, top["fleet"])})
    return read_mac(r, top["mac"], sides)
