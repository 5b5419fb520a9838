#!/usr/bin/env python3
"""Air efficiency as deployed: message bodies as a share of each saturated packet, captured at
the far DESERT port behind real bridge processes, this build beside a baseline, in one run.

    .venv/bin/python benchmarks/air_bench.py [--seconds 20] [--baseline REV | --baseline none]
                                             [--domain 62] [--only NAME,...]

Each scenario builds a package from a small manifest (`uwgen build`), starts the emulator
(lossless, recording every packet it delivers), starts two real bridges (`uwgen bridge`
processes, surface and vehicle, each in its own ROS domain) and floods the surface side's
topics from an rclpy publisher: more messages than the link can carry, so every packet could
be full. Every packet the vehicle's DESERT port received from the surface in the measuring
window (after a warm-up) is decoded with the build's own frame and envelope decoders:

- `bodies`: the messages' bodies (the fields, after H, id and length bytes; both parts of a
  cut message, wire-format.md section 14.2) over max_read_length, per packet, averaged;
- `written`: the bytes the bridge wrote per packet over max_read_length (frame, heads, tag);
- `msgs/pkt` and, per topic, messages delivered (a topic at 0 is starved).

The baseline is the same script run by a subprocess on another commit's code (`git archive
REV` into a temporary folder, put first on PYTHONPATH): its own generated package, its own
bridges, its own decoders. Default baseline: the commit this branch started from (today's
figures). The goals are docs/wire-format.md section 14's: bodies >= 0.8 of a saturated 64 B
packet on FIFO traffic of packed and native Twists, >= 0.7 with three latest topics, >= 0.9
at 128 B; no topic at 0 (a strict topic among them, "strict and three 64", takes every packet's
head: the others must still be served).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "f60c0ca"        # the commit before cut messages (wire format 4): "today"
PERIOD = 0.2

PACKED_FIELDS = """\
    profile: packed
    fields:
      linear.x: {min: -2, max: 2, precision: 2, out_of_range: clamp}
      linear.y: {min: -2, max: 2, precision: 2, out_of_range: clamp}
      linear.z: {static: 0}
      angular.x: {static: 0}
      angular.y: {static: 0}
      angular.z: {min: -3.2, max: 3.2, precision: 2, out_of_range: clamp}
"""


def topic(name: str, ident: int, queue: str, extra: str = "") -> str:
    q = "queue: fifo\n    depth: 50" if queue == "fifo" else "queue: latest"
    if queue == "strict":
        q = "queue: latest\n    strict: true"
    return (f"  - name: {name}\n    id: {ident}\n    type: geometry_msgs/msg/Twist\n"
            f"    publisher: surface\n    {q}\n" + extra)


# name: (max_read_length, [(topic, id, queue, packed)], publish rate per topic in Hz)
SCENARIOS = {
    "packed fifo 64": (64, [("/packed", 4, "fifo", True)], 150.0),
    "native fifo 64": (64, [("/native", 5, "fifo", False)], 40.0),
    "three latest 64": (64, [("/a", 11, "latest", False), ("/b", 12, "latest", False),
                             ("/c", 40, "latest", False)], 20.0),
    "strict and three 64": (64, [("/s", 9, "strict", False), ("/a", 11, "latest", False),
                                 ("/b", 12, "latest", False), ("/c", 40, "latest", False)], 20.0),
    "packed fifo 128": (128, [("/packed", 4, "fifo", True)], 250.0),
    "native fifo 128": (128, [("/native", 5, "fifo", False)], 60.0),
}
GOALS = {"packed fifo 64": 0.8, "native fifo 64": 0.8, "three latest 64": 0.7,
         "strict and three 64": 0.7,
         "packed fifo 128": 0.9, "native fifo 128": 0.9}


def manifest(mrl: int, topics) -> str:
    out = ("network: airbench\npackage: uwgen_airbench\nfragment_id: 250\nsides:\n"
           f"  surface: {{port: 4000, sender_id: 1, link: {{max_read_length: {mrl}, period: {PERIOD}}}}}\n"
           f"  vehicle: {{port: 4001, sender_id: 2, link: {{max_read_length: {mrl}, period: {PERIOD}}}}}\n"
           "topics:\n")
    for name, ident, queue, packed in topics:
        out += topic(name, ident, queue, PACKED_FIELDS if packed else "")
    return out


def env_for(domain: int) -> dict:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONUNBUFFERED="1")
    return env


def analyse(deliveries, mrl: int, t0: float, t1: float) -> dict:
    """Body share and bytes written per packet of the surface's packets in [t0, t1), with this
    build's decoders (whatever its frame and envelope are)."""
    from uwgen.runtime.wire import envelope
    from uwgen.runtime.wire import framing
    packets = bodies = written = messages = 0
    per_id: dict[int, int] = {}
    cut_tail = getattr(envelope, "CUT_TAIL", None)      # builds before wire format 4 cut nothing
    # the build's own frame: the short one where it has it (it also reads long frames)
    decoder = (framing.ShortFrameDecoder() if hasattr(framing, "ShortFrameDecoder")
               else framing.FrameDecoder())
    for d in deliveries:
        if d.source != "surface" or not t0 <= d.time < t1:
            continue
        frames = decoder.feed(d.data)
        packets += 1
        written += len(d.data)
        for f in frames:
            try:
                e = envelope.decode(f)
            except envelope.EnvelopeError:
                continue
            for m in e.messages:
                bodies += len(m.body)
                if m.kind == cut_tail:
                    continue                 # a cut message counts once, at its head
                messages += 1
                per_id[m.id] = per_id.get(m.id, 0) + 1
    n = max(packets, 1)
    return {"packets": packets, "bodies": bodies / (n * mrl), "written": written / (n * mrl),
            "msgs_per_packet": messages / n, "per_id": per_id,
            "pace": packets / ((t1 - t0) / PERIOD)}


def twist(k: int, packed: bool):
    from geometry_msgs.msg import Twist, Vector3
    if packed:
        return Twist(linear=Vector3(x=0.01 * (k % 300) - 1.5, y=0.5 - 0.01 * (k % 90)),
                     angular=Vector3(z=0.01 * (k % 600) - 3.0))
    return Twist(linear=Vector3(x=0.3 + 0.01 * (k % 50), y=0.0, z=float(k % 7)),
                 angular=Vector3(x=0.0, y=0.0, z=0.1 * (k % 7) - 0.3))


def measure(name: str, seconds: float, domain: int, warmup: float = 4.0) -> dict:
    """Run one scenario on the code first on sys.path; its figures."""
    import rclpy
    from geometry_msgs.msg import Twist
    from rclpy.context import Context
    from uwgen.emulator import NodeSpec, Scenario, run_emulator

    mrl, topics, rate = SCENARIOS[name]
    root = Path(tempfile.mkdtemp(prefix="uwgen_airbench_"))
    (root / "uwgen.yaml").write_text(manifest(mrl, topics))
    build = subprocess.run([sys.executable, "-m", "uwgen.cli", "--quiet", "build", "-m",
                            str(root / "uwgen.yaml"), "-o", str(root / "generated" / "uwgen_airbench")],
                           env=env_for(domain), capture_output=True, text=True)
    if build.returncode != 0:
        raise SystemExit(f"uwgen build failed:\n{build.stderr}")
    scen = Scenario(nodes=[NodeSpec("surface", position=(0.0, 0.0, 0.0), dest="vehicle"),
                           NodeSpec("vehicle", position=(500.0, 0.0, 0.0), dest="surface")],
                    period=PERIOD, max_read_length=mrl, bitrate=4800.0, per=0.0, seed=1)
    procs = []
    with run_emulator(scen, record=True) as emu:
        try:
            for side, dom in (("surface", domain), ("vehicle", domain + 1)):
                procs.append(subprocess.Popen(
                    [sys.executable, "-m", "uwgen.cli", "--quiet", "bridge", "-m",
                     str(root / "uwgen.yaml"), "--side", side, "--package-dir",
                     str(root / "generated"), "--port", str(emu.port(side)),
                     "--status-period", "0"],
                    env=env_for(dom), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE))
            ctx = Context()
            rclpy.init(context=ctx, domain_id=domain,
                       signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
            node = rclpy.create_node("air_bench_publisher", context=ctx)
            pubs = [(node.create_publisher(Twist, t, 100), packed) for t, _, _, packed in topics]
            stop = threading.Event()

            def flood():
                k = 0
                while not stop.wait(1.0 / rate):
                    k += 1
                    for pub, packed in pubs:
                        pub.publish(twist(k, packed))
            thread = threading.Thread(target=flood, daemon=True)
            thread.start()
            deadline = time.monotonic() + 30.0     # bridges up and matched
            while time.monotonic() < deadline and not any(
                    d.source == "surface" for d in emu.deliveries("vehicle")):
                time.sleep(0.2)
            start = emu._now() + warmup
            time.sleep(warmup + seconds)
            stop.set()
            thread.join()
            result = analyse(emu.deliveries("vehicle"), mrl, start, start + seconds)
            node.destroy_node()
            rclpy.shutdown(context=ctx)
        finally:
            for p in procs:
                p.terminate()
            for p in procs:
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
    result["ids"] = [ident for _, ident, _, _ in topics]
    return result


def baseline_results(rev: str, names: list[str], seconds: float, domain: int) -> dict:
    """The same scenarios on commit `rev`'s code, in a subprocess."""
    tree = Path(tempfile.mkdtemp(prefix="uwgen_airbench_base_"))
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "uwgen", "templates",
                              "pyproject.toml"], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    env = env_for(domain)
    env["PYTHONPATH"] = str(tree)
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--measure-only",
                          "--seconds", str(seconds), "--domain", str(domain),
                          "--only", ",".join(names)], env=env, capture_output=True, text=True,
                         cwd=str(tree))
    if out.returncode != 0:
        raise SystemExit(f"baseline run failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="measuring window per scenario")
    parser.add_argument("--baseline", default=BASELINE,
                        help="commit to compare with (its code, same scenarios), or `none`")
    parser.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "62")),
                        help="ROS domain of the surface side (the vehicle's is the next one)")
    parser.add_argument("--only", default=",".join(SCENARIOS), help="scenarios, comma-separated")
    parser.add_argument("--measure-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    names = [n for n in args.only.split(",") if n]
    if args.measure_only:
        print(json.dumps({n: measure(n, args.seconds, args.domain) for n in names}))
        return
    base = ({} if args.baseline == "none"
            else baseline_results(args.baseline, names, args.seconds, args.domain + 2))
    now = {n: measure(n, args.seconds, args.domain) for n in names}
    print("Bodies as a share of each saturated packet, captured at the far DESERT port behind "
          f"real bridges ({args.seconds:.0f} s each; baseline {args.baseline})")
    print(f"{'scenario':<21}{'base bodies':>12}{'written':>9}{'msgs/pkt':>9}"
          f"{'bodies':>8}{'written':>9}{'msgs/pkt':>9}{'pace':>6}  goal")
    for n in names:
        r, b = now[n], base.get(n)
        left = (f"{b['bodies']:>12.2f}{b['written']:>9.2f}{b['msgs_per_packet']:>9.1f}"
                if b else f"{'-':>12}{'-':>9}{'-':>9}")
        goal = GOALS[n]
        print(f"{n:<21}{left}{r['bodies']:>8.2f}{r['written']:>9.2f}{r['msgs_per_packet']:>9.1f}"
              f"{r['pace']:>6.2f}  >= {goal}: {'ok' if r['bodies'] >= goal else 'MISS'}")
    for n in names:
        starved = [i for i in now[n]["ids"]
                   if not now[n]["per_id"].get(str(i), now[n]["per_id"].get(i, 0))]
        if starved:
            print(f"{n}: topic ids {starved} got no message (a topic at 0: MISS)")
        if len(now[n]["ids"]) > 1:
            ids = now[n]["ids"]
            counts = {i: now[n]["per_id"].get(str(i), now[n]["per_id"].get(i, 0)) for i in ids}
            print(f"{n}: messages per topic id {counts}"
                  + (f" (baseline {dict((i, base[n]['per_id'].get(str(i), 0)) for i in ids)})"
                     if n in base else ""))


if __name__ == "__main__":
    main()
