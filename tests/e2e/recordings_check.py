"""Checks of a demo run's recordings (tests/e2e/test_demo_cli.py runs the demo once for
these and its other checks): one MCAP recording per side, the standard reader opens them, their ROS
messages decode to what the vehicle published, and `uwgen log` on them prints the demo
report's rows (same counts; latencies as LATENCY_BELOW_MS and LATENCY_ABOVE_MS explain)."""
from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path

from uwgen import tether

ROOT = Path(__file__).resolve().parents[2]

ROW = re.compile(r"^(/\S+)\s+(\w+ → \w+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+(?: \(\d+\))?)"
                 r"\s+(\d+)\s+(-|\d+ ms)\s+(-|\d+ ms)$", re.M)


# Both latencies end when the far bridge publishes (the applications record a received
# message at its source timestamp, docs/demo.md). They start at the publisher's source
# timestamp, stamped inside its publish call (the recording), and at the application's record
# just after that call returns (the report). So the recording's latency is never shorter (but
# for the cells' rounding to 1 ms), and longer by the publish call's tail: under 1 ms on a
# quiet machine, 8 ms seen at the median of a CI run on 2 loaded cores.
LATENCY_BELOW_MS = 1.0
LATENCY_ABOVE_MS = 50.0


def uwgen(*args, timeout=60):
    """`python -m uwgen.cli ARGS` of this checkout (what else is on PYTHONPATH stays)."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    return tether.run([sys.executable, "-m", "uwgen.cli", *args], capture_output=True, text=True,
                      timeout=timeout, env=dict(os.environ, PYTHONPATH=path), cwd=ROOT)


def rows(text: str) -> dict[str, tuple]:
    return {m.group(1): m.groups()[1:] for m in ROW.finditer(text)}


def ms(cell: str) -> float | None:
    return None if cell == "-" else float(cell.split()[0])


def check_recordings(tmp_path: Path, stdout: str) -> None:
    """What a finished demo run in `tmp_path` (its report: `stdout`) must have recorded."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from uwgen.demo.records import f32

    files = [tmp_path / "bridge_surface.mcap", tmp_path / "bridge_vehicle.mcap"]
    assert (tmp_path / "link.png").stat().st_size > 10_000

    # The vehicle bridge's recording: poses and log lines decode to what the vehicle published.
    records = [json.loads(line) for line in (tmp_path / "vehicle.jsonl").read_text().splitlines()]
    published = {(r["x"], r["y"], r["theta"], r["v"], r["w"]) for r in records if r["ev"] == "pose"}
    logs = {r["seq"]: r["size"] for r in records if r["ev"] == "log"}
    with open(files[1], "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_summary() is not None                # finished: summary and footer
        poses, lines = [], []
        for _schema, channel, _msg, m in reader.iter_decoded_messages(
                topics=["/turtle1/pose", "/vehicle/log"]):
            if channel.topic == "/turtle1/pose":
                poses.append((f32(m.x), f32(m.y), f32(m.theta), f32(m.linear_velocity),
                              f32(m.angular_velocity)))
            else:
                lines.append(m.data)
    assert len(poses) > 50 and set(poses) <= published
    for text in lines:                                         # "[seq] text" of `size` characters
        seq = int(text[1:text.index("]")])
        assert len(text) == len(f"[{seq}] ") + logs[seq], text
    assert lines

    # uwgen log on the two recordings prints the report's rows.
    log = uwgen("log", *map(str, files), timeout=60)
    assert log.returncode == 0, log.stderr
    demo_rows, log_rows = rows(stdout), rows(log.stdout)
    assert set(demo_rows) == set(log_rows) == {"/turtle1/cmd_vel", "/turtle1/pose",
                                               "/vehicle/battery", "/vehicle/log"}
    for topic, demo_row in demo_rows.items():
        got = log_rows[topic]
        assert got[:8] == demo_row[:8], (topic, demo_row, got)        # every count
        for a, b in zip(demo_row[8:], got[8:]):                        # p50 and p95
            assert (a == b == "-") or (
                -LATENCY_BELOW_MS <= ms(b) - ms(a) <= LATENCY_ABOVE_MS), (topic, demo_row, got)
