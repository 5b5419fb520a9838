"""A surface/vehicle pair of LinkGuards, each holding its side's lock in a temporary folder,
with manual clocks (a monotonic one, and a wall clock that starts at WALL0)."""
from __future__ import annotations

from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire.codec import pack_items, peek_header
from uwgen.security.guard import GuardConfig, LinkGuard

KEY = bytes(range(32))
OTHER_KEY = bytes(range(100, 132))
SURFACE, VEHICLE = 1, 2
WALL0 = 1_790_000_000.0          # a wall time (late 2026) for the manual wall clocks
# Every id of this little manifest is protected: cmd_vel encrypted, log signed, a service signed.
MODES = {4: "encrypt", 7: "sign", 20: "sign"}
MANIFEST_IDS = set(MODES)
FINGERPRINTS = {4: bytes.fromhex("a1b2c3d4e5f60718")}


def config(sender: int, peer: int, peer_name: str, modes=None, tag_bytes: int = 8) -> GuardConfig:
    return GuardConfig("demo", sender, {peer: peer_name}, dict(MODES if modes is None else modes),
                       dict(FINGERPRINTS), tag_bytes=tag_bytes)


def surface(folder, key=KEY, clock=None, wall=None, **kw) -> LinkGuard:
    return LinkGuard.for_key(key, config(SURFACE, VEHICLE, "vehicle"), folder / "surface.lock",
                             clock=clock or ManualClock(), wall=wall or ManualClock(WALL0),
                             name="surface", **kw)


def vehicle(folder, key=KEY, clock=None, wall=None, **kw) -> LinkGuard:
    return LinkGuard.for_key(key, config(VEHICLE, SURFACE, "surface"), folder / "vehicle.lock",
                             clock=clock or ManualClock(), wall=wall or ManualClock(WALL0),
                             name="vehicle", **kw)


def twist(x: float = 1.0) -> bytes:
    """An unprotected cmd_vel payload (id 4): six float fields."""
    return pack_items([0, 4, x, 0.0, 0.0, 0.0, 0.0, -0.25])


def log_line(text: str = "hello") -> bytes:
    return pack_items([0, 7, text])


def request(seq: int, flag: bool = True) -> bytes:
    return pack_items([2, 20, seq, flag])


def dropped(guard: LinkGuard) -> int:
    return guard.stats()["dropped"]


def passes_to_bridge(payload: bytes | None) -> bool:
    """Whether the guard handed on something the bridge would route to a manifest entry."""
    if payload is None:
        return False
    try:
        return peek_header(payload)[1] in MANIFEST_IDS
    except ValueError:
        return False
