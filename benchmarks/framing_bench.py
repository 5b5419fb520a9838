"""Throughput of the frame decoder (MB/s of input) on clean and noisy streams.

    .venv/bin/python benchmarks/framing_bench.py [--mb 8] [--chunk 64]

Streams: frames with random payloads (1..255 bytes), cut into `--chunk`-byte reads (DESERT hands out
packets of max_read_length bytes). "noisy": one slice in 20 lost and random garbage inserted;
"garbage": random bytes only (the decoder hunting all the time).
"""
from __future__ import annotations

import argparse
import random
import time

from uwgen.runtime.wire.framing import FrameDecoder, encode_frame


def clean_stream(rng: random.Random, size: int) -> bytes:
    out = bytearray()
    while len(out) < size:
        out += encode_frame(rng.randbytes(rng.randint(1, 255)))
    return bytes(out)


def noisy_stream(rng: random.Random, size: int, chunk: int) -> bytes:
    clean = clean_stream(rng, size)
    out = bytearray()
    for i in range(0, len(clean), chunk):
        if rng.random() < 0.05:
            continue                                  # a lost packet
        if rng.random() < 0.05:
            out += rng.randbytes(rng.randint(1, 32))  # garbage
        out += clean[i:i + chunk]
    return bytes(out)


def measure(stream: bytes, chunk: int, repeat: int = 3) -> tuple[float, int]:
    chunks = [stream[i:i + chunk] for i in range(0, len(stream), chunk)]
    best = float("inf")
    frames = 0
    for _ in range(repeat):
        d = FrameDecoder()
        t0 = time.perf_counter()
        frames = 0
        for c in chunks:
            frames += len(d.feed(c))
        best = min(best, time.perf_counter() - t0)
    return len(stream) / best / 1e6, frames


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=float, default=8.0, help="stream size in MB")
    ap.add_argument("--chunk", type=int, default=64, help="bytes per read")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rng = random.Random(args.seed)
    size = int(args.mb * 1e6)
    streams = {
        "clean": clean_stream(rng, size),
        "noisy": noisy_stream(rng, size, args.chunk),
        "garbage": rng.randbytes(size),
    }
    for chunk in sorted({args.chunk, 4096}):
        for name, stream in streams.items():
            mbps, frames = measure(stream, chunk)
            print(f"{name:8s} chunk {chunk:5d} B: {mbps:8.1f} MB/s  ({frames} frames from {len(stream) / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
