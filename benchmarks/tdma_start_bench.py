#!/usr/bin/env python3
"""TDMA start benchmark (docs/emulator.md, "How a TDMA bridge times its writes"; wire-format.md
section 15.5, the exchange at start): how long after both bridges start a service call is
answered, with none of the first packets lost, with the surface's first packet lost, with
the vehicle's and with both, against the same build made to listen before its first blind
write (the rule for a guard shorter than a packet and the range) and, with both lost, made
to space its blind writes four frames apart (`slot_timing.blind_frames`), same run.

    .venv/bin/python benchmarks/tdma_start_bench.py [--at 3] [--repeats 2]

commands_bench's link and TDMA (frame 3 s, guard 0.8 s, 1000 m, 64 B every 0.2 s: the guard
covers a packet and the range) with no random loss: the emulator loses exactly the named
sides' first packets. Both bridges start together; the call leaves `--at` seconds later (3 s,
as commands_bench's first call) and fails after the service's 12 s timeout. Per case it
prints each repeat's seconds from the start to the answer (or `failed`), and when each side
first heard the other. The repeats start the bridges at phases spread over DESERT's frame.
Uses ROS_DOMAIN_ID and the next one.
"""
from __future__ import annotations

import argparse
import random
import sys
import time

from test_msgs.srv import BasicTypes

from uwgen.bridge.node import BridgeNode
from uwgen.bridge.plan import BridgePlan
from uwgen.emulator.server import Emulator
from uwgen.runtime.link import slot_timing

from commands_bench import Side, build_package   # the same manifest and ROS sides
from commands_sim import scenario

TIMEOUT = 12.0      # the bench manifest's /echo timeout
FRAME = 3.0         # commands_sim's TDMA frame: the repeats start the bridges across it


def lose_first(emu: Emulator, sources: tuple[str, ...]) -> dict[str, float]:
    """The emulator loses each of `sources`' first packet (counted `lost_per`); returns
    {receiver: when it first got a packet, in the emulator's time}, filled as packets arrive."""
    core, first, lost = emu._core, {}, set()
    rx_end = core._rx_end

    def rx(arr, t):
        pkt, r = arr.packet, core._nodes[arr.receiver]
        if pkt.source in sources and pkt.dest == r.name and pkt.source not in lost:
            lost.add(pkt.source)
            r.rx.remove(arr)
            if r.locked is arr:
                r.locked = None
            r.counters.inc("lost_per")
            return None
        before = r.counters["packets_delivered"]
        rx_end(arr, t)
        if r.counters["packets_delivered"] > before:
            first.setdefault(r.name, t)
    core._rx_end = rx
    return first


def trial(package, lost: tuple[str, ...], at: float, mode: str, phase: float) -> tuple[float | None, dict]:
    """One start, the bridges `phase` s after DESERT's (the emulator's) frame began; `mode`:
    "this build", "listen" or "four" (the references)."""
    scen = scenario(0.0, 1, "tdma")
    emu = Emulator(scen)
    first = lose_first(emu, lost)
    safe, spacing = slot_timing.blind_safe, slot_timing.blind_frames
    if mode == "listen":
        slot_timing.blind_safe = lambda config, link: False
    if mode == "four":
        slot_timing.blind_frames = lambda config, link: 4
    emu.start()
    time.sleep(phase)
    sides = {}
    try:
        sides = {name: Side(name) for name in ("surface", "vehicle")}
        t0 = time.monotonic()
        for name, side in sides.items():
            plan = BridgePlan.from_package(package, name)
            side.executor.add_node(BridgeNode(plan, plan.options(port=emu.port(name), status_period=0),
                                              context=side.context, rng=random.Random(1)))

        def serve(req, resp):
            resp.int32_value = req.int32_value * 3
            return resp
        sides["vehicle"].node.create_service(BasicTypes, "/echo", serve)
        client = sides["surface"].node.create_client(BasicTypes, "/echo")
        client.wait_for_service(timeout_sec=10.0)
        time.sleep(max(0.0, t0 + at - time.monotonic()))
        future = client.call_async(BasicTypes.Request(int32_value=7))
        deadline = time.monotonic() + TIMEOUT
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.02)
        answered = (time.monotonic() - t0 if future.done() and future.result() is not None
                    and future.result().int32_value == 21 else None)
        # the emulator's time runs on the loop's clock (time.monotonic) from emu._t0
        return answered, {k: v + emu._t0 - t0 for k, v in first.items()}
    finally:
        slot_timing.blind_safe, slot_timing.blind_frames = safe, spacing
        for side in sides.values():
            side.close()
        emu.stop()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--at", type=float, default=3.0, help="s after the start the call leaves")
    ap.add_argument("--repeats", type=int, default=3,
                    help="starts per case, the bridges at phases spread over the frame")
    args = ap.parse_args()
    package = build_package("tdma")
    print(f"| first packet lost | mode | answered (s after start; call at {args.at:g} s, "
          f"{TIMEOUT:g} s timeout) | first packet heard by vehicle / surface (s) |")
    print("|---|---|---|---|")
    names = {"listen": "reference (listens first)", "four": "reference (blind writes 4 frames apart)",
             "this build": "this build"}
    for lost in ((), ("surface",), ("vehicle",), ("surface", "vehicle")):
        for mode in ("listen", "four", "this build") if len(lost) == 2 else ("listen", "this build"):
            got = [trial(package, lost, args.at, mode, k * FRAME / args.repeats)
                   for k in range(args.repeats)]
            cells = ", ".join("failed" if a is None else f"{a:.1f}" for a, _ in got)
            heard = ", ".join("/".join(f"{h.get(s, float('nan')):.1f}" for s in ("vehicle", "surface"))
                              for _, h in got)
            print(f"| {' and '.join(lost) or 'none'} | {names[mode]} | "
                  f"{cells} | {heard} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
