"""CPU use of the emulator with 2, 8 and 32 nodes at full load, and how it grows.

    /work/main/.venv/bin/python benchmarks/emulator_bench.py [--nodes 2 8 32] [--seconds 60]
        [--sockets 5]

Full load: every node always has a packet waiting (64 B every 0.2 s at 4800 bit/s,
CSMA-ALOHA, the SNR model at wind 0), nodes spread over a 1 km square, each sending to
the next (unicast; every other node still hears and is interfered by the packet).

"core": the sans-IO core alone, `--seconds` of simulated time as fast as it goes. "CPU
per simulated s" is the share of one core the emulator needs to keep up in real time.
Every packet sent reaches N - 1 receivers, so the work per simulated second grows as
N * (N - 1); the table compares each row with the 2-node reference of the same run
(measured / reference, and the N(N-1) prediction).

"sockets" (with --sockets S): the real emulator (asyncio shell in its thread) with one
TCP client per node writing a packet per period, run for S wall seconds; CPU of this
whole process (shell, core, and the clients, which only write and read) per wall second.
"""
from __future__ import annotations

import argparse
import math
import random
import socket
import threading
import time

from uwgen.emulator import EmulatorCore, NodeSpec, Scenario, SnrModel, run_emulator


def fleet(n: int, seed: int = 1) -> Scenario:
    rng = random.Random(seed)
    names = [f"n{i}" for i in range(n)]
    nodes = [NodeSpec(name, position=(rng.uniform(0, 1000), rng.uniform(0, 1000), 50.0),
                      dest=names[(i + 1) % n]) for i, name in enumerate(names)]
    return Scenario(nodes=nodes, period=0.2, max_read_length=64, bitrate=4800.0,
                    snr=SnrModel(wind=0.0), seed=seed)


def run_core(n: int, seconds: float) -> dict:
    scen = fleet(n)
    core = EmulatorCore(scen)
    names = scen.names()
    per_node = int(seconds / scen.period) + 2          # always something waiting
    for name in names:
        core.client_attached(name, 0.0)
        core.client_data(name, 0.0, bytes(64 * per_node))
    c0 = time.process_time()
    core.advance(seconds)
    cpu = time.process_time() - c0
    counters = core.all_counters()
    sent = sum(c["packets_sent"] for c in counters.values())
    delivered = sum(c["packets_delivered"] for c in counters.values())
    return {"n": n, "cpu": cpu, "sent": sent, "delivered": delivered,
            "arrivals": sent * (n - 1), "per_sim_s": cpu / seconds}


def run_sockets(n: int, wall: float) -> dict:
    scen = fleet(n)
    stop = threading.Event()
    with run_emulator(scen) as emu:
        socks = [socket.create_connection(("127.0.0.1", emu.port(name))) for name in scen.names()]

        def writer() -> None:
            payload = bytes(64)
            next_t = time.monotonic()
            while not stop.is_set():
                for s in socks:
                    s.sendall(payload)
                next_t += scen.period
                time.sleep(max(0.0, next_t - time.monotonic()))

        def reader() -> None:
            for s in socks:
                s.setblocking(False)
            while not stop.is_set():
                for s in socks:
                    try:
                        s.recv(65536)
                    except BlockingIOError:
                        pass
                time.sleep(0.05)

        threads = [threading.Thread(target=writer), threading.Thread(target=reader)]
        c0, w0 = time.process_time(), time.monotonic()
        for t in threads:
            t.start()
        time.sleep(wall)
        stop.set()
        for t in threads:
            t.join()
        cpu, elapsed = time.process_time() - c0, time.monotonic() - w0
        counters = emu.all_counters()
        for s in socks:
            s.close()
    return {"n": n, "cpu_share": cpu / elapsed,
            "sent": sum(c["packets_sent"] for c in counters.values()),
            "delivered": sum(c["packets_delivered"] for c in counters.values())}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nodes", type=int, nargs="+", default=[2, 8, 32])
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds (core)")
    parser.add_argument("--sockets", type=float, default=0.0, metavar="S",
                        help="also run the socket emulator for S wall seconds per size")
    args = parser.parse_args()

    rows = [run_core(n, args.seconds) for n in args.nodes]
    ref = rows[0]
    print(f"core: {args.seconds:g} simulated s, full load, CSMA-ALOHA + SNR model; "
          f"reference: {ref['n']} nodes")
    print(f"{'nodes':>5} {'sent':>6} {'delivered':>9} {'arrivals':>9} {'CPU s':>7} "
          f"{'CPU per sim s':>13} {'us/arrival':>10} {'x ref':>7} {'N(N-1) pred':>11}")
    for r in rows:
        pred = (r["n"] * (r["n"] - 1)) / (ref["n"] * (ref["n"] - 1))
        print(f"{r['n']:5d} {r['sent']:6d} {r['delivered']:9d} {r['arrivals']:9d} "
              f"{r['cpu']:7.3f} {100 * r['per_sim_s']:12.2f}% "
              f"{1e6 * r['cpu'] / max(1, r['arrivals']):10.1f} "
              f"{r['cpu'] / ref['cpu']:7.1f} {pred:11.1f}")
    if len(rows) >= 2:
        a, b = rows[0], rows[-1]
        exponent = math.log(b["cpu"] / a["cpu"]) / math.log(b["n"] / a["n"])
        print(f"growth: CPU ~ N^{exponent:.2f} between {a['n']} and {b['n']} nodes "
              f"(N(N-1) gives N^{math.log(b['n'] * (b['n'] - 1) / (a['n'] * (a['n'] - 1))) / math.log(b['n'] / a['n']):.2f})")
    if args.sockets > 0:
        print(f"\nsockets: real-time emulator, one client per node writing 64 B per period, "
              f"{args.sockets:g} s each")
        print(f"{'nodes':>5} {'sent':>6} {'delivered':>9} {'CPU share of one core':>22}")
        for n in args.nodes:
            r = run_sockets(n, args.sockets)
            print(f"{r['n']:5d} {r['sent']:6d} {r['delivered']:9d} {100 * r['cpu_share']:21.1f}%")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
