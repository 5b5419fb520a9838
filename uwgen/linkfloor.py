"""The smallest `max_read_length` a side's link can run with (docs/wire-format.md section 14).

DESERT's range is 1..4096 bytes per packet, but a wire format 2 packet carries more than its
messages: the short frame's length byte (framing.SHORT_OVERHEAD), the envelope's P and W
(envelope.HEAD), the reliability hooks' T and A parts (delivery.reliability.OVERHEAD), and on a
secured link the seal's tag, K, T and C (packet_seal.max_overhead of the manifest's tag length).
What is left must hold the smallest fragment (fragment.MIN_COMPACT_PAYLOAD), the piece every
message longer than a packet is cut into. A link below that cannot send a message at all (the
bridge ended in a ValueError from the fragmenter for every value below the floor).

A wire format 1 link (profile rmw_desert on the network) has no envelope: its frames cross
packets (section 1), so every value of DESERT's range works.

    floor = min_read_length(wire_format=2, tag_bytes=8)     # 44
    check_read_lengths(manifest)                          # ManifestError(s) at each side
"""
from __future__ import annotations

from uwgen.errors import Collector
from uwgen.manifest.model import Manifest
from uwgen.manifest.loader import ManifestErrors
from uwgen.manifest.nodes import ManifestError
from uwgen.manifest.sides import DESERT_MAX_READ_LENGTH
from uwgen.runtime.delivery.reliability import OVERHEAD as RELIABILITY_OVERHEAD
from uwgen.runtime.link.mac import TurnMac
from uwgen.runtime.wire.envelope import HEAD as ENVELOPE_HEAD
from uwgen.runtime.wire.fragment import MIN_COMPACT_PAYLOAD
from uwgen.runtime.wire.framing import SHORT_OVERHEAD as FRAME_OVERHEAD
from uwgen.security.packet_seal import max_overhead


def min_read_length(wire_format: int, tag_bytes: int | None, mac_bytes: int = 0) -> int:
    """The least bytes per packet a link of `wire_format` can send a message with;
    `tag_bytes`: the seal's tag length when the link is secured, else None; `mac_bytes`: what
    the MAC's C items add (mode turns: uwgen.runtime.link.turn_mac.TurnMac.overhead)."""
    if wire_format != 2:
        return 1
    seal = max_overhead(tag_bytes) if tag_bytes is not None else 0
    return FRAME_OVERHEAD + ENVELOPE_HEAD + RELIABILITY_OVERHEAD + seal + mac_bytes + MIN_COMPACT_PAYLOAD


def why_floor(wire_format: int, tag_bytes: int | None) -> str:
    """What the floor is made of, for messages."""
    if wire_format != 2:
        return "wire format 1 frames cross packets"
    seal = f", the seal's {max_overhead(tag_bytes)} (its tag of {tag_bytes})" if tag_bytes is not None else ""
    return (f"a packet holds the frame's {FRAME_OVERHEAD} byte, the envelope's {ENVELOPE_HEAD}, the "
            f"reliability parts' {RELIABILITY_OVERHEAD}{seal} and a fragment of at least "
            f"{MIN_COMPACT_PAYLOAD}")


def link_floor(manifest: Manifest) -> tuple[int, str]:
    """(the least max_read_length of every side of `manifest`, why)."""
    wire = 1 if manifest.uses_rmw_desert() else 2      # as BridgePlan.wire_format
    tag = manifest.security.tag_bytes if manifest.protected() else None
    mac = TurnMac.overhead if manifest.mac.mode == "turns" else 0
    why = why_floor(wire, tag) + (f", and {mac} for the MAC's turn items" if mac and wire == 2 else "")
    return min_read_length(wire, tag, mac), why


def check_read_lengths(manifest: Manifest) -> None:
    """ManifestError (located at the side's entry) for each side whose link is
    below `link_floor`; all of them at once (ErrorList) when several."""
    floor, why = link_floor(manifest)
    errors = Collector()
    for side in manifest.sides.values():
        n = side.link.max_read_length
        if n < floor:
            errors.add(ManifestError(side.where,
                                     f"max_read_length {n} of side '{side.name}' is too small for this "
                                     f"network: at least {floor} ({why})"))
    errors.raise_if_any(ManifestErrors)


def check_option(max_read_length: int, wire_format: int, tag_bytes: int | None,
                 mac_bytes: int = 0) -> str | None:
    """Why a --max-read-length given on a command line cannot work, or None."""
    floor = min_read_length(wire_format, tag_bytes, mac_bytes)
    if not floor <= max_read_length <= DESERT_MAX_READ_LENGTH:
        return (f"max_read_length {max_read_length} must be {floor}..{DESERT_MAX_READ_LENGTH} on this "
                f"network ({why_floor(wire_format, tag_bytes)}; DESERT crashes above "
                f"{DESERT_MAX_READ_LENGTH})")
    return None
