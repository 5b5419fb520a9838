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
import string
from pathlib import Path

from cryptography.hazmat.primitives import hashes
from cryptography.hazmat.primitives.kdf.hkdf import HKDF

from uwgen.safefile import UnreadableFile, read_bytes, shown
from uwgen.security.errors import SecurityError
from uwgen.security.files import write_private

MASTER_KEY_BYTES = 32
SENDER_KEY_BYTES = 16          # AES-128, as AES-CCM-16-64-128
KEY_ID_BYTES = 8
HKDF_SALT = b"uwgen secure link v1"
KEY_FILE_LIMIT = 64 * 1024    # a key and its comments; anything longer is not a key file
KEY_FILE_HEADER = ("# uwgen network master key: keep it secret, give every side of the network "
                   "a copy (owner-only permissions).\n")


__all__ = ["SecurityError", "sender_key", "working_key", "new_epoch", "key_id", "new_master_key", "write_key_file",
           "read_key_file", "KeyFileMissing"]


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


class KeyFileMissing(SecurityError):
    """There is no key file at the path (the bridge says where it looked and why)."""


def _owner_only(path: Path):
    def check(info: os.stat_result) -> None:
        if info.st_mode & (stat.S_IRWXG | stat.S_IRWXO):
            raise SecurityError(f"key file {shown(path)} is accessible to others (mode "
                                f"{stat.S_IMODE(info.st_mode):o}); make it owner-only: chmod 600 {shown(path)}")
    return check


def read_key_file(path: Path) -> bytes:
    """The master key in `path`; SecurityError if missing, malformed or readable by others.

    The file is read with `uwgen.safefile` (a regular file only, at most KEY_FILE_LIMIT
    bytes, its mode checked before any byte is read): a symlink to /dev/zero, a FIFO or a
    loop is refused at once instead of read forever. An all-zero key is refused: it is the
    placeholder of examples and tests, which anyone can guess, so a link sealed with it is
    open to every stranger; a warning would let such a link run."""
    path = Path(path)
    try:
        data = read_bytes(path, "key file", KEY_FILE_LIMIT, check=_owner_only(path))
    except UnreadableFile as exc:
        if exc.missing:
            raise KeyFileMissing(f"{exc}: create one with `uwgen keygen {shown(path)}` and copy it "
                                "to every side") from None
        raise SecurityError(str(exc)) from None
    expected = f"one line of {2 * MASTER_KEY_BYTES} hex digits ({MASTER_KEY_BYTES} bytes)"
    lines = [(n, ln) for n, ln in enumerate(data.split(b"\n"), 1)
             if ln.strip() and not ln.lstrip().startswith(b"#")]
    if len(lines) != 1:
        raise SecurityError(f"key file {shown(path)} must hold {expected} besides '#' comment lines, "
                            f"found {len(lines)} such lines")
    number, line = lines[0]
    for column, byte in enumerate(line, 1):
        if chr(byte) not in string.hexdigits and not bytes([byte]).isspace():   # ASCII spaces only
            shown_byte = repr(chr(byte)) if 32 <= byte < 127 else f"the byte 0x{byte:02x}"
            raise SecurityError(f"key file {shown(path)}:{number}:{column}: {shown_byte} is not a hex "
                                f"digit (0-9, a-f); a key file holds {expected}")
    digits = b"".join(line.split()).decode("ascii")
    if len(digits) != 2 * MASTER_KEY_BYTES:
        raise SecurityError(f"key file {shown(path)}:{number}: the key has {len(digits)} hex digits "
                            f"({len(digits) / 2:g} bytes); a key is {expected}")
    key = bytes.fromhex(digits)
    if not any(key):
        raise SecurityError(f"key file {shown(path)}:{number}: the key is all zeros, a placeholder anyone "
                            f"can guess: refused. Make a real key with `uwgen keygen` and copy it to every side")
    return key
