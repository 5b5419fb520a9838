"""Erasure code for repair fragments: k data blocks + r repair blocks, any k of the k + r rebuild.

The code is zfec's (Luigi Rizzo's systematic Vandermonde code over GF(2^8), as used by
Tahoe-LAFS), a maintained C extension: a library, not our own arithmetic. Its generator is
written down in docs/wire-format.md section 11, and tests/runtime/test_fec.py recomputes it from
that formula with plain Python, so the wire format does not depend on the library:

- GF(2^8) with the polynomial x^8 + x^4 + x^3 + x^2 + 1 (0x11D), alpha = x (0x02);
- V is the (k + r) x k matrix with row 0 = (1, 0, ..., 0) and row i >= 1 = (alpha^((i-1)*j)) for
  j = 0..k-1; the generator is G = V * inverse(V[0..k-1]), so its first k rows are the identity
  (block i < k is data block i) and repair block k + j is row k + j of G applied to the data blocks.

All blocks of one message have the same length: the last data block is padded with zero bytes to
the length of the others (the receiver knows the real size from the repair fragments).
"""
from __future__ import annotations

import zfec

MAX_BLOCKS = 256          # zfec's limit on k + r


def _check(k: int, r: int) -> None:
    if not 1 <= k or r < 0 or k + r > MAX_BLOCKS:
        raise ValueError(f"need 1 <= k and 0 <= r with k + r <= {MAX_BLOCKS}, got k={k}, r={r}")


def repair_blocks(data: list[bytes], r: int) -> list[bytes]:
    """The r repair blocks for k equal-length data blocks (blocks k .. k + r - 1)."""
    k = len(data)
    _check(k, r)
    if r == 0:
        return []
    if len({len(b) for b in data}) != 1:
        raise ValueError("data blocks must all have the same length")
    return [bytes(b) for b in zfec.Encoder(k, k + r).encode(tuple(data), tuple(range(k, k + r)))]


def rebuild(k: int, r: int, blocks: dict[int, bytes]) -> list[bytes]:
    """The k data blocks from any k of the k + r blocks (`blocks` maps block number -> bytes)."""
    _check(k, r)
    if len(blocks) < k:
        raise ValueError(f"need {k} blocks to rebuild, have {len(blocks)}")
    if any(not 0 <= n < k + r for n in blocks):
        raise ValueError(f"block numbers must be in 0..{k + r - 1}, got {sorted(blocks)}")
    if all(n in blocks for n in range(k)):
        return [bytes(blocks[n]) for n in range(k)]
    # Prefer data blocks (no arithmetic for them), then the lowest repair blocks.
    chosen = sorted(blocks, key=lambda n: (n >= k, n))[:k]
    out = zfec.Decoder(k, k + r).decode(tuple(blocks[n] for n in chosen), tuple(chosen))
    return [bytes(b) for b in out]
