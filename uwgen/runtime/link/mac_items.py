"""The turn MAC's C items (docs/wire-format.md section 16): `2S NN` grants sender S the turn
for NN packets (`2S 00`: notice that one of the leader's next two packets grants it), `3S`
ends S's turn.
Pure bytes; `uwgen.runtime.link.turn_mac.TurnMac` writes and reads them."""
from __future__ import annotations

from dataclasses import dataclass

TURN_GRANT = 2          # C item `2S NN`: the turn goes to sender S for NN packets (1..255);
                        # `2S 00`: notice that one of the leader's next two packets
                        # grants S its turn
TURN_END = 3            # C item `3S`: sender S ends its turn


@dataclass(frozen=True)
class MacItem:
    code: int
    sender: int
    count: int = 0      # TURN_GRANT: packets granted (0: a notice of the grant to come)


def encode_items(items: list[MacItem]) -> bytes:
    out = bytearray()
    for it in items:
        if not 0 <= it.sender <= 15:
            raise ValueError(f"MAC item for sender {it.sender}: a sender id fits 4 bits")
        out.append((it.code << 4) | it.sender)
        if it.code == TURN_GRANT:
            if not 0 <= it.count <= 255:
                raise ValueError(f"a turn grant is for 1..255 packets (0: a notice), got {it.count}")
            out.append(it.count)
    return bytes(out)


def decode_items(control: bytes) -> list[MacItem]:
    """The MAC's items among a C part's bytes (others skipped; total, never fails: a grant
    cut short by the part's end is ignored)."""
    out, i = [], 0
    while i < len(control):
        code, sender = control[i] >> 4, control[i] & 0x0F
        if code == TURN_GRANT:
            if i + 1 < len(control):
                out.append(MacItem(code, sender, control[i + 1]))
            i += 2
            continue
        if code == TURN_END:
            out.append(MacItem(code, sender))
        i += 1
    return out
