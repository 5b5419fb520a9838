#!/usr/bin/env python3
"""Reads a commands_bench --trace file and prints, for each failed call or goal, what
happened to its messages between its round's start and the next round: every offer (first
or copy), every packet carrying one, every arrival and every refusal at the receiving judge,
in seconds from the round's start. With --all it prints every round.

Then, under the turns MAC, how each side's whole turns lost were repaired: a turn is a run of
one side's packets with none of the other side's written between; lost whole, every packet
of it was lost on the channel (the emulator's account). Counted are the lost turns that
carried an answer, a result, a request or a goal whose peer then reported (a packet with an
A part that arrived before the side's next turn): how many of them had their commands
again in the side's very next turn (wire-format.md section 15.6: the report settles the
turn, `settled_by`, and each side repairs its own leg at once) and how many waited longer.

Last, per kind of command message, the copies the bridges offered and did not take back
before they left, and how many of them were offered after the message had already arrived
at the peer (no loss asked for them).

    python benchmarks/trace_commands.py TRACE.jsonl [--all]
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from collections import deque

COMMANDS = ("09", "14")    # commands_bench's /fib and /echo ids, as hex


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trace")
    ap.add_argument("--all", action="store_true")
    args = ap.parse_args()
    rows = [json.loads(line) for line in open(args.trace) if line.strip().startswith("{")]
    rounds = [r for r in rows if r.get("ev") == "round"]
    failed = {}
    for r in rows:
        if r.get("ev") == "failed":
            failed.setdefault(r["i"], []).append(r["what"])
    for k, start in enumerate(rounds):
        i = start["i"]
        if not args.all and i not in failed:
            continue
        end = rounds[k + 1]["t"] if k + 1 < len(rounds) else float("inf")
        print(f"== round {i}: failed {failed.get(i, [])}")
        for r in rows:
            if "t" not in r or not start["t"] <= r["t"] < end or r.get("ev") in ("round",):
                continue
            ev = r.get("ev")
            t = r["t"] - start["t"]
            if ev == "packet":
                cmds = [m for m in r["m"] if m[2:4] in ("14", "09")]
                if cmds:
                    print(f"  {t:6.2f} {r['side'][:3]} packet #{r['no']} {' '.join(cmds)}")
            elif ev in ("offer", "in"):
                print(f"  {t:6.2f} {r['side'][:3]} {ev:5s} {r['p']}")
            elif ev == "refused" and r["key"] in (9, 20):
                print(f"  {t:6.2f} {r['side'][:3]} REFUSED key {r['key']} age {r['age']}")
            elif ev == "failed":
                print(f"  {t:6.2f} FAILED {r['what']}")
    for side, (lost, again) in lost_turns(rows).items():
        print(f"{side}: {lost} whole turns lost with a command and reported on; "
              f"{again} had it again in the next own turn, {lost - again} later")
    print("copies the bridges offered (not taken back) after the peer already had the message: "
          + ", ".join(f"{kind} {late}/{n}" for kind, (n, late) in sorted(late_copies(rows).items())))
    return 0


KINDS = {("02", "14"): "request", ("03", "14"): "response", ("02", "09"): "goal or result request",
         ("03", "09"): "goal answer or result"}
REUSED = 100.0    # s: an equal payload offered this much later is a new message (a reused handle)


def late_copies(rows: list[dict]) -> dict[str, tuple[int, int]]:
    """Per kind of command message: (copies the bridges offered, those offered after the
    message had already arrived at the peer): a copy no loss asked for (the report that said
    it arrived, or its answer, was lost). A message's copies are its offers after the first,
    less those taken back before they left; an equal payload offered REUSED s after the one
    before is a new message."""
    events: dict[str, dict[tuple[str, str], list[float]]] = {"in": {}, "offer": {}, "withdrawn": {}}
    for r in rows:
        if r.get("ev") in events:
            events[r["ev"]].setdefault((r["side"], r["p"]), []).append(r["t"])
    out: dict[str, tuple[int, int]] = {}
    for (side, payload), times in events["offer"].items():
        kind = KINDS.get((payload[:2], payload[2:4]))
        if kind is None:
            continue
        peer = events["in"].get(("vehicle" if side == "surface" else "surface", payload), [])
        back = events["withdrawn"].get((side, payload), [])
        first = times[0]
        for k, t in enumerate(times[1:], 1):
            if t - first > REUSED:
                first = t
                continue
            after = times[k + 1] if k + 1 < len(times) else float("inf")
            if any(t <= w < after for w in back):
                continue                      # taken back before it left: no air time
            n, late = out.get(kind, (0, 0))
            out[kind] = (n + 1, late + any(first <= a < t for a in peer))
    return out


def lost_turns(rows: list[dict]) -> dict[str, tuple[int, int]]:
    """Per side: (whole turns lost that carried a command and that the peer reported on,
    those whose next own turn carried a command of it again) (module doc)."""
    packets, pending, by_emu = [], {"surface": deque(), "vehicle": deque()}, {}
    for r in rows:
        if r.get("ev") == "packet" and r.get("side") in pending:
            p = {"t": r["t"], "side": r["side"], "ack": r["ack"], "lost": False, "n": r["n"],
                 "cmds": [b for b in r.get("bare", []) if b[:2] in ("02", "03") and b[2:4] in COMMANDS]}
            pending[r["side"]].append(p)
            packets.append(p)
        elif r.get("ev") == "emu":
            sent = re.match(r"[\d.]+ (\w+): sends packet (\d+) \((\d+) B\)", r["msg"])
            queue = pending.get(sent.group(1)) if sent else None
            # the emulator's packet is the oldest built one of its size (a frame byte more):
            # one built but not written (the connection's late drop) is skipped, and lost
            while queue and queue[0]["n"] + 1 != int(sent.group(3)):
                queue.popleft()["lost"] = True
            if queue:
                by_emu[int(sent.group(2))] = queue.popleft()
            lost = re.match(r"[\d.]+ \w+: packet (\d+) from \w+ lost", r["msg"])
            if lost and int(lost.group(1)) in by_emu:
                by_emu[int(lost.group(1))]["lost"] = True
    turns: list[list[dict]] = []
    for p in packets:
        if turns and turns[-1][0]["side"] == p["side"]:
            turns[-1].append(p)
        else:
            turns.append([p])
    out = {}
    for side in ("surface", "vehicle"):
        lost = again = 0
        for k, turn in enumerate(turns):
            cmds = {b for p in turn for b in p["cmds"]}
            if turn[0]["side"] != side or not cmds or not all(p["lost"] for p in turn):
                continue
            mine = [j for j in range(k + 1, len(turns)) if turns[j][0]["side"] == side]
            if not mine:
                continue
            between = [p for t in turns[k + 1:mine[0]] for p in t]
            if not any(p["ack"] and not p["lost"] for p in between):
                continue                      # the peer heard nothing, or its report was lost
            lost += 1
            again += any(b in cmds for p in turns[mine[0]] for b in p["cmds"])
        out[side] = (lost, again)
    return out


if __name__ == "__main__":
    sys.exit(main())
