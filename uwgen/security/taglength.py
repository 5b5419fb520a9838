"""Telling a peer built with another tag length from a forger (docs/wire-format.md 12.2).

A link's tag length (`security: {tag_bytes}`: 4, 6 or 8) is not in the packet's bytes: both
sides take it from the manifest they were built from. Two sides built from manifests that
differ there split every packet at the wrong place, so every packet fails its tag, and the
schema announcements that would name the difference ride in those packets too. So, for a
sync packet that failed its tag, `other_length` tries the other allowed lengths under the
sender's key of the epoch the packet names: if one verifies, the sender holds the network's
key and seals with that length. The packet is still dropped (counted `tag_length`, never
delivered); the operator reads which length each side uses instead of a stream of `bad_tag`.

Cost: at most two more key derivations and tag checks per sync packet that fails its tag,
so at most the link's packet rate (a few per second). A forger gains nothing: nothing is
delivered, and a forged packet makes the log name a length with odds 2^-32 at best.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from uwgen.runtime.wire import envelope as env
from uwgen.security import packetwire


def other_length(data: bytes, own: int, aead_for: Callable[[int, bytes, int], Any],
                 encrypts: Callable[[env.Message], bool],
                 fingerprint: Callable[[int], bytes]) -> int | None:
    """The tag length other than `own` under which sync packet `data` verifies, or None.
    `aead_for(sender, epoch, tag_bytes)` is the sender's AES-CCM of that epoch."""
    for length in env.TAG_LENGTHS:
        if length == own:
            continue
        try:
            e = env.decode(data, length)
        except env.EnvelopeError:
            continue
        if e.sync is None or not e.sealed:
            continue
        seq = e.sync.high * env.NUMBER_MOD + e.number     # K's bits 12-43, W's low 12
        aead = aead_for(e.sender, e.sync.epoch, length)
        if packetwire.open_envelope(aead, e, seq, encrypts, fingerprint) is not None:
            return length
    return None
