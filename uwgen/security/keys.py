"""Network master keys and the per-sender keys derived from them.

A key file holds one 32-byte network master key as 64 hex digits (comment lines start
with '#'). Every side of a network has a copy; it never appears in the manifest. Each
sender's AES-128 key is derived with HKDF-SHA256 (RFC 5869) from the master key, the
network name and the sender id, as OSCORE derives its sender keys (RFC 8613, 3.2.1):
two senders never share a key, so they can never reuse a (key, nonce) pair, and one key
file used for two networks still gives unrelated keys.
"""
from __future__ import annotations

import os
import secrets
import stat
from pathlib import Path

from cryptography.hazmat.primitives import hashes
from cryptography.hazmat.primitives.kdf.hkdf import HKDF

from uwgen.security.errors import SecurityError
from uwgen.security.files import write_private

MASTER_KEY_BYTES = 32
SENDER_KEY_BYTES = 16          # AES-128, as AES-CCM-16-64-128
KEY_ID_BYTES = 8
HKDF_SALT = b"uwgen secure link v1"
KEY_FILE_HEADER = ("# uwgen network master key: keep it secret, give every side of the network "
                   "a copy (owner-only permissions).\n")


__all__ = ["SecurityError", "sender_key", "working_key", "new_epoch", "key_id", "new_master_key", "write_key_file",
           "read_key_file"]


def _hkdf(master: bytes, info: bytes, length: int) -> bytes:
    return HKDF(algorithm=hashes.SHA256(), length=length, salt=HKDF_SALT, info=info).derive(master)


def sender_key(master: bytes, network: str, sender: int) -> bytes:
    """The AES-128 key of `sender` (0..15) in `network`."""
    return _hkdf(master, b"sender key\x00" + network.encode() + b"\x00" + bytes([sender]),
                 SENDER_KEY_BYTES)


def working_key(master: bytes, network: str, sender: int, epoch: bytes) -> bytes:
    """The AES-128 key `sender` seals with during `epoch` (6 random bytes, new at every start):
    HKDF as `sender_key`, with the epoch in the info, as OSCORE's appendix B.2 re-keying mixes
    a fresh nonce into its key derivation. A new epoch is a new key, so its numbers may start
    at 0 again without ever repeating a (key, nonce) pair: no state file is needed for that."""
    return _hkdf(master, b"working key\x00" + network.encode() + b"\x00" + bytes([sender]) + epoch,
                 SENDER_KEY_BYTES)


def new_epoch(nbytes: int = 6) -> bytes:
    """A fresh random epoch (from the OS's CSPRNG)."""
    return secrets.token_bytes(nbytes)


def key_id(master: bytes, network: str) -> str:
    """A public name of the key (hex), safe to log: tells which key a side runs with, never the key."""
    return _hkdf(master, b"key id\x00" + network.encode(), KEY_ID_BYTES).hex()


def new_master_key() -> bytes:
    return secrets.token_bytes(MASTER_KEY_BYTES)


def write_key_file(path: Path, key: bytes | None = None, force: bool = False) -> bytes:
    """Write a new key file readable by its owner only (0600); refuse to replace one unless
    `force`. Returns the key."""
    path = Path(path)
    key = new_master_key() if key is None else key
    if len(key) != MASTER_KEY_BYTES:
        raise SecurityError(f"a master key has {MASTER_KEY_BYTES} bytes, not {len(key)}")
    if os.path.lexists(path) and not force:
        raise SecurityError(f"{path} exists: not replacing a key (every side using it would stop "
                            "understanding this one); use --force to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    write_private(path, (KEY_FILE_HEADER + key.hex() + "\n").encode())
    return key


def read_key_file(path: Path) -> bytes:
    """The master key in `path`; SecurityError if missing, malformed or readable by others."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
        text = path.read_text(encoding="ascii")
    except FileNotFoundError:
        raise SecurityError(f"key file {path} not found: create one with `uwgen keygen {path}` "
                            "and copy it to every side") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SecurityError(f"cannot read key file {path}: {exc}") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise SecurityError(f"key file {path} is accessible to others (mode {stat.S_IMODE(mode):o}); "
                            f"make it owner-only: chmod 600 {path}")
    lines = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if len(lines) != 1:
        raise SecurityError(f"key file {path} must hold one line of {2 * MASTER_KEY_BYTES} hex digits")
    try:
        key = bytes.fromhex(lines[0])
    except ValueError:
        raise SecurityError(f"key file {path}: the key is not hex digits") from None
    if len(key) != MASTER_KEY_BYTES:
        raise SecurityError(f"key file {path}: the key has {len(key)} bytes, expected {MASTER_KEY_BYTES}")
    return key
