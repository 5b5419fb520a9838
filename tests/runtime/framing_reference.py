"""A deliberately naive model of wire format section 2, used as the oracle for the decoder tests.

It reads the spec's sentence literally, on the whole received stream at once, one position at a time,
and reports where each delivered frame sits in the stream so tests can reason about damage.
"""
from __future__ import annotations


def reference_frames(stream: bytes) -> list[tuple[int, int, bytes]]:
    """(start, end_inclusive, payload) of every frame a receiver delivers from this stream."""
    out = []
    i = 0
    while i + 1 < len(stream):
        if stream[i] == 0x99 and stream[i + 1] == 0x99:
            if i + 2 >= len(stream):
                break                        # LEN never arrived
            n = stream[i + 2]
            term = i + 3 + n
            if n == 0:
                i += 1                       # mismatch: discard the first 0x99
                continue
            if term >= len(stream):
                break                        # incomplete at end of stream: not delivered
            if stream[term] == 0x55:
                out.append((i, term, stream[i + 3:term]))
                i = term + 1
                continue
            i += 1                           # mismatch: discard the first 0x99
            continue
        i += 1
    return out
