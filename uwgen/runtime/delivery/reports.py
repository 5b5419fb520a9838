"""The A part's reports (docs/wire-format.md section 15.2): what a receiver says about one
peer's packets, their bytes, and 12-bit packet numbers unwrapped. Pure."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

NUMBER_BITS = 12
NUMBER_MOD = 1 << NUMBER_BITS
MAX_BITMAP = 15                  # bytes of bitmap a report may carry (4 bits of R0)
DELAY_UNIT = 0.25                # s: the ack delay's unit in R1
MAX_DELAY_UNITS = 15


class AckError(ValueError):
    """An A part that is not a list of well-formed reports."""


@dataclass(frozen=True)
class Report:
    """What a receiver says about one peer's packets: `largest` (mod 4096) was received
    `delay` seconds before the report left; bit i of `bitmap` (i = 0 the packet just below
    largest) says whether largest - 1 - i was received, for `nbytes` * 8 packets."""

    peer: int
    largest: int
    bitmap: int = 0
    nbytes: int = 0
    delay: float = 0.0

    def numbers(self) -> tuple[list[int], list[int]]:
        """(received, missing) numbers mod 4096, largest first."""
        got, missing = [self.largest], []
        for i in range(8 * self.nbytes):
            n = (self.largest - 1 - i) % NUMBER_MOD
            (got if self.bitmap >> (8 * self.nbytes - 1 - i) & 1 else missing).append(n)
        return got, missing


def encode_reports(reports: Iterable[Report]) -> bytes:
    """R0 = peer (bits 7-4) | bitmap bytes n (3-0); R1 = delay in 1/4 s (7-4) | largest
    bits 11-8 (3-0); R2 = largest bits 7-0; then n bitmap bytes, packet largest-1 first."""
    out = bytearray()
    for r in reports:
        if not 0 <= r.peer <= 15 or not 0 <= r.nbytes <= MAX_BITMAP or not 0 <= r.largest < NUMBER_MOD:
            raise AckError(f"report {r} out of range")
        units = min(MAX_DELAY_UNITS, max(0, int(r.delay / DELAY_UNIT)))
        out += bytes([r.peer << 4 | r.nbytes, units << 4 | r.largest >> 8, r.largest & 0xFF])
        out += r.bitmap.to_bytes(r.nbytes, "big")
    return bytes(out)


def decode_reports(data: bytes) -> list[Report]:
    reports, i = [], 0
    while i < len(data):
        if i + 3 > len(data):
            raise AckError(f"report at byte {i} is cut short ({len(data) - i} of 3 head bytes)")
        r0, r1, r2 = data[i], data[i + 1], data[i + 2]
        n = r0 & 0x0F
        if i + 3 + n > len(data):
            raise AckError(f"report at byte {i} announces {n} bitmap bytes, "
                           f"{len(data) - i - 3} remain")
        reports.append(Report(r0 >> 4, (r1 & 0x0F) << 8 | r2,
                              int.from_bytes(data[i + 3:i + 3 + n], "big"), n,
                              (r1 >> 4) * DELAY_UNIT))
        i += 3 + n
    return reports


def unwrap(number: int, near: int) -> int:
    """The int whose low 12 bits are `number`, closest to `near`."""
    base = near - NUMBER_MOD // 2
    return base + (number - base) % NUMBER_MOD
