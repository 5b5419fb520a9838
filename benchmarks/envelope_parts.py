"""Table 0 of envelope_bench.py: the demo's mix as bridges send it, part by part.

`air_parts` splits the air bytes of wire format 2+ packets by part (docs/wire-format.md
section 14.3), `baseline` runs the same table on another commit's code, `print_table0` prints
both; `SimWall` is the wall clock the bridges' hooks stamp T with, following the simulation;
`breakdown` splits table 1's air bytes (frames, packet and message heads, security, bodies).
"""
from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from uwgen.runtime.clock import ManualClock
from uwgen.runtime.wire import envelope

from uwgen.runtime.wire.framing import FrameDecoder

try:            # wire format 3's short frame (it reads long frames too)
    from uwgen.runtime.wire.framing import ShortFrameDecoder
except ImportError:     # a baseline build: the long frame only
    ShortFrameDecoder = FrameDecoder

DESERT_HEADER = 4
PARTS = ("DESERT", "frame", "P", "W", "K", "T", "A", "C", "msg head", "N, age", "tag", "body")


class SimWall:
    """A wall clock that follows the simulation's clock (table 0's bridges stamp T with it)."""

    def __init__(self, clock: ManualClock, start: float = 1.7e9):
        self.clock, self.start = clock, start

    def now(self) -> float:
        return self.start + self.clock.now()


def counting_heads(pair, hooks):
    """`hooks` counting into `pair.message_items` the reliability heads on the air: what the
    receiver's admit takes off (N, age), less the age items unshape puts back, which were not
    sent (wire-format.md section 14.3; a build without unshape has none)."""
    admit, unshape = hooks.admit, getattr(hooks, "unshape", None)

    def counted_admit(payload: bytes, now: float, **kw) -> bytes | None:
        out = admit(payload, now, **kw)
        pair.message_items += len(payload) - (len(out) if out is not None else len(payload))
        return out

    def uncounted(e):
        out = unshape(e)
        pair.message_items -= sum(len(m.body) for m in out.messages) - sum(len(m.body) for m in e.messages)
        return out
    return dataclasses.replace(hooks, admit=counted_admit, **({"unshape": uncounted} if unshape else {}))


def part_bytes(e) -> int:
    """Bytes of K, T, A and C in envelope `e` (what its head holds besides P and W)."""
    return ((envelope.SYNC_LEN if e.sync is not None else 0) + (envelope.TIME_LEN if e.time is not None else 0)
            + sum(1 + len(x) for x in (e.ack, e.control) if x is not None))


def air_parts(batches: list[bytes], tag_bytes: int, message_items: int) -> dict[str, int]:
    """Air bytes by part: DESERT's header, the frame, each envelope part (P, W, K, T, A, C),
    message heads (H, id, length and run bytes), the reliability heads of messages on the air
    (N, age: `message_items`, what the receivers' admit took off less what unshape put back),
    the tag and the bodies (the rest: seq, handles, fields, fragment heads)."""
    out = dict.fromkeys(PARTS, 0)
    out["DESERT"] = DESERT_HEADER * len(batches)
    for batch in batches:
        frames = ShortFrameDecoder().feed(batch)
        out["frame"] += len(batch) - sum(map(len, frames))
        for f in frames:
            e = envelope.decode(f, tag_bytes)
            out["P"] += 1
            out["W"] += len(e.encode_head()) - 1 - part_bytes(e)
            out["K"] += envelope.SYNC_LEN if e.sync is not None else 0
            out["T"] += envelope.TIME_LEN if e.time is not None else 0
            out["A"] += 1 + len(e.ack) if e.ack is not None else 0
            out["C"] += 1 + len(e.control) if e.control is not None else 0
            out["tag"] += len(e.tag) if e.sealed else 0
            bodies = sum(len(m.body) for m in e.messages)
            out["msg head"] += len(f) - e.head_size() - bodies
            out["body"] += bodies
    out["N, age"] = message_items
    out["body"] -= message_items
    return out


def baseline(script: Path, root: Path, rev: str, seconds: float) -> dict:
    """`script`'s `as_deployed` on commit `rev`'s code (git archive of `root` into a temporary
    folder, first on PYTHONPATH; the script and the demo's generated package as they are here)."""
    tree = Path(tempfile.mkdtemp(prefix="uwgen_envbench_base_"))
    archive = subprocess.run(["git", "-C", str(root), "archive", rev, "uwgen"],
                             capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, str(script), "--deployed-json",
                          "--seconds", str(seconds)], env=env, capture_output=True, text=True,
                         cwd=str(tree))
    if out.returncode != 0:
        raise SystemExit(f"baseline run failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def breakdown(batches: list[bytes], wire: int, tag_bytes: int, security: int) -> dict[str, int]:
    """Air bytes by what they carry: DESERT's header, frames, packet heads (P, W and
    parts; wire format 2), message heads (kind and id items; H, id and length bytes),
    security (what protection added) and bodies (the rest: seq, handles, fields)."""
    out = dict.fromkeys(("DESERT", "frame", "packet head", "message head", "security", "body"), 0)
    out["DESERT"] = DESERT_HEADER * len(batches)
    out["security"] = security
    for batch in batches:
        frames = (ShortFrameDecoder() if wire == 2 else FrameDecoder()).feed(batch)
        out["frame"] += len(batch) - sum(map(len, frames))
        for f in frames:
            if wire == 2:
                e = envelope.decode(f, tag_bytes)
                tag = len(e.tag) if e.sealed else 0            # the per-packet seal's
                out["packet head"] += e.head_size() - tag
                out["security"] += tag
                bodies = sum(len(m.body) for m in e.messages)
                out["message head"] += len(f) - e.head_size() - bodies
                out["body"] += bodies
            else:
                m = envelope.from_v1(f)
                out["message head"] += len(f) - len(m.body)
                out["body"] += len(m.body)
    out["body"] -= security
    return out


def print_table0(rev: str, base: dict, now: dict) -> None:
    print("Table 0: the demo's mix as bridges send it (both ways at once, their reliability hooks; "
          "secured: the per-packet seal, 8-byte tag): air bytes per delivered message")
    print(f"{'':<12}{'baseline ' + rev:>20}{'this build':>12}{'goal':>8}")
    for label, goal in (("unsecured", 15.0), ("secured", 21.0)):
        print(f"{label:<12}{base[label]:>20.1f}{now[label]:>12.1f}{goal:>8.0f}  "
              f"{'ok' if now[label] <= goal else 'MISS'}")
    print("what they carry, bytes per delivered message (P, W, K, T, A, C: the envelope's "
          "parts; msg head: H, id, length and run bytes; N, age: reliability heads):")
    print(f"{'':<22}" + "".join(f"{k:>9}" for k in PARTS))
    for label in ("unsecured", "secured"):
        for which, figures in (("baseline", base), ("this build", now)):
            split = figures.get(label + " parts")
            if split is not None:
                print(f"{label + ', ' + which:<22}" + "".join(f"{split.get(k, 0):>9.2f}" for k in PARTS))
    print()
