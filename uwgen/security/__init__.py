"""The secure link (docs/wire-format.md section 12, docs/security.md).

A protected payload is the ordinary payload with its fields signed or encrypted by
AES-CCM with an 8-byte tag (AES-CCM-16-64-128, as OSCORE, RFC 8613), under a working key
that HKDF derives from one network master key, the sender id and the sender's epoch: a
random value new at every start, so no nonce depends on anything kept on disk. It is
protected WHOLE, as it leaves, before the link fragments it, and checked after the link
reassembles it. On a wire format 2 link the same keys, epochs and receiving rules seal each
packet once instead (docs/wire-format.md section 12.2).

    keys.py       key files (`uwgen keygen`), per-sender and per-epoch key derivation
    wire.py       the protected layout: security word, sync word, nonce, aad, seal/open
    epochs.py     the sender's epoch and numbers; the epochs a receiver keeps per sender
    window.py     the replay window of one (sender, epoch): bounded jumps, overtaken times
    freshness.py  the sync word's time and the max-age check (wall clocks passed in)
    receiver.py   the receiving rules (epoch, freshness, replay), shared by every seal
    droplog.py    drop counters with throttled logs
    files.py      private file writes (no symlink followed) and the one-copy-per-side lock
    guard.py      LinkGuard: what a wire format 1 link calls to protect and to check payloads
    packetwire.py the per-packet seal of wire format 2: one tag per envelope (pure)
    control.py    the envelope's C part: sync requests, and their rate limits
    packet_seal.py PacketSeal: the packet hooks of a wire format 2 link (seal, open, K, T, C)
"""
from uwgen.security.errors import SecurityError

__all__ = ["SecurityError"]
