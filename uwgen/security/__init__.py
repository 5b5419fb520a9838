"""The secure link (issue 9, docs/wire-format.md section 12).

A protected payload is the ordinary payload with its fields signed or encrypted by
AES-CCM with an 8-byte tag (AES-CCM-16-64-128, as OSCORE, RFC 8613), under a key that
HKDF derives per sender from one network master key. It is protected WHOLE before the
link fragments it and checked after the link reassembles it.

    keys.py    key files (`uwgen keygen`) and per-sender key derivation
    wire.py    the protected layout: security word, nonce, authenticated data, seal/open
    window.py  the per-sender replay window and sequence reconstruction
    state.py   the state file: sequence blocks reserved before use, replay floors
    guard.py   LinkGuard: what a link calls to protect and to check payloads, with
               drop counters per reason and throttled logs
"""
from uwgen.security.keys import SecurityError

__all__ = ["SecurityError"]
