"""Bridge recordings: written by BridgeRecorder, read back by uwgen log, standard tools decode
them; cut short, full disk, rotation and bad input."""
from __future__ import annotations

import json
import os
import zlib
from pathlib import Path
from types import SimpleNamespace

import pytest
from geometry_msgs.msg import Twist
from std_msgs.msg import String

from uwgen.bridge.recorder import BridgeRecorder, RecordOptions
from uwgen.cli import main as uwgen_main
from uwgen.fieldkit.reader import RecordingError, read_file, read_recordings
from uwgen.fieldkit.summary import format_summary, summarise

LINK = SimpleNamespace(max_read_length=64, period=0.2)


class Wall:
    """A system clock the test moves."""

    def __init__(self, t: float = 1_790_000_000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


def recorder(path: Path, side: str, topics: dict, wall: Wall, **kw) -> BridgeRecorder:
    rec = BridgeRecorder(RecordOptions(path, **kw.pop("opts", {})), network="net", side=side,
                         link_config=LINK, topics=topics, wall=wall, **kw)
    for name, cls in (("/cmd", Twist), ("/log", String)):
        if name in topics:
            rec.topic(name, cls)
    return rec


def twist(x: float) -> Twist:
    t = Twist()
    t.linear.x = float(x)
    return t


def two_sides(tmp_path: Path, n: int = 5, lose: set[int] = frozenset()):
    """A surface that sends n twists (payload = a stand-in byte string) and a vehicle that
    receives all but `lose`; each message in its own packet."""
    wall = Wall()
    topics_s, topics_v = {"/cmd": "out"}, {"/cmd": "in"}
    s = recorder(tmp_path / "s.mcap", "surface", topics_s, wall)
    v = recorder(tmp_path / "v.mcap", "vehicle", topics_v, wall)
    for k in range(n):
        payload = b"cmd%d" % k
        wall.t += 0.1
        s.message("/cmd", twist(k), payload, published=wall.t - 0.05)
        s.packet(0.0, "tx", payload, "sent")
        wall.t += 0.5
        if k not in lose:
            v.packet(0.0, "rx", payload, "delivered 1")
            v.message("/cmd", twist(k), payload, listeners=1)
    acc_out = {"published": n, "taken": n, "dropped_by_subscription": 0,
               "dropped_by_policy": {"superseded": 0}, "queued": 0, "sent": n}
    acc_in = {"received": n - len(lose), "lost_on_link": 0, "delivered": n - len(lose),
              "dropped_on_receive": {"decode_error": 0}}
    s.status({"topics": {"/cmd": {"accounting": acc_out, "link": {}}}}, final=True)
    v.status({"topics": {"/cmd": {"accounting": acc_in}}}, final=True)
    s.close()
    v.close()
    return tmp_path / "s.mcap", tmp_path / "v.mcap"


def test_recordings_of_both_sides_give_the_table_latency_and_losses(tmp_path):
    s, v = two_sides(tmp_path, n=5, lose={2})
    summary = summarise(read_recordings([s, v]))
    row = summary.topics[0]
    assert (row.name, row.published, row.on_link, row.lost, row.delivered) == ("/cmd", 5, 5, 1, 4)
    assert len(row.latencies) == 4 and all(abs(x - 0.55) < 1e-6 for x in row.latencies)
    assert summary.sides["surface"].lost == 1          # one packet never read by the vehicle
    text = format_summary(summary)
    assert "550 ms" in text and "duplicates delivered: none" in text


def test_recorded_messages_decode_with_the_standard_ros2_decoder(tmp_path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    s, _ = two_sides(tmp_path, n=3)
    with open(s, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        got = [(ch.topic, schema.name, msg.sequence, decoded.linear.x)
               for schema, ch, msg, decoded in reader.iter_decoded_messages(topics=["/cmd"])]
    assert got == [("/cmd", "geometry_msgs/msg/Twist", zlib.crc32(b"cmd%d" % k), float(k))
                   for k in range(3)]


def test_a_payload_received_twice_is_a_duplicate(tmp_path):
    wall = Wall()
    s = recorder(tmp_path / "s.mcap", "surface", {"/log": "out"}, wall)
    v = recorder(tmp_path / "v.mcap", "vehicle", {"/log": "in"}, wall)
    s.message("/log", String(data="x"), b"p1", published=wall.t)
    for _ in range(2):
        wall.t += 1.0
        v.message("/log", String(data="x"), b"p1", listeners=1)
    s.close()
    v.close()
    assert summarise(read_recordings([tmp_path / "s.mcap", tmp_path / "v.mcap"])).duplicates == {"/log": 1}


def test_messages_published_to_no_subscriber_are_not_delivered(tmp_path):
    wall = Wall()
    v = recorder(tmp_path / "v.mcap", "vehicle", {"/log": "in"}, wall)
    v.message("/log", String(data="a"), b"a", listeners=1)
    wall.t += 1
    v.message("/log", String(data="b"), b"b", listeners=0)
    v.close()
    rec = read_file(tmp_path / "v.mcap")
    assert [m.heard for m in rec.messages["/log"]] == [True, False]
    assert summarise([rec]).topics[0].delivered == 1


def cut(path: Path, keep: int) -> None:
    data = path.read_bytes()
    path.write_bytes(data[:keep])


def test_a_recording_cut_short_is_read_up_to_its_last_complete_chunk(tmp_path, capsys):
    wall = Wall()
    path = tmp_path / "s.mcap"
    rec = recorder(path, "surface", {"/log": "out"}, wall)
    for k in range(30):
        wall.t += 1
        rec.message("/log", String(data=f"line {k}"), b"%d" % k, published=wall.t)
        if k in (9, 19):
            rec.out.sync()                # chunks end here, as the writer's timer would
            if k == 19:
                end_of_second = rec.out._stream.tell()
    rec.close()
    cut(path, end_of_second + 40)          # inside the third chunk: it and the summary are gone
    got = read_file(path)
    assert [m.data for m in got.messages["/log"]] == [
        m.data for m in read_file_complete(tmp_path, wall)][:20]
    assert got.ends and "last complete chunk (2 chunks" in got.ends[0] and str(path) in got.ends[0]
    assert uwgen_main(["log", str(path)]) == 0
    out = capsys.readouterr().out
    assert "cut short; read up to its last complete chunk" in out and "ending at" in out


def read_file_complete(tmp_path: Path, wall: Wall):
    """The same 30 messages, recorded whole."""
    path = tmp_path / "whole.mcap"
    rec = recorder(path, "surface", {"/log": "out"}, Wall(wall.t))
    for k in range(30):
        rec.message("/log", String(data=f"line {k}"), b"%d" % k)
    rec.close()
    return read_file(path).messages["/log"]


class FullDisk:
    """A file that takes `room` bytes, then fails as a full disk does."""

    def __init__(self, path: Path, room: int):
        self.f = open(path, "wb")
        self.room = room

    def write(self, data: bytes) -> int:
        if self.f.tell() + len(data) > self.room:
            raise OSError(28, "No space left on device")
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)


def test_a_full_disk_stops_the_recording_and_keeps_what_was_written(tmp_path, caplog):
    wall = Wall()
    path = tmp_path / "s.mcap"
    rec = recorder(path, "surface", {"/log": "out"}, wall,
                   opener=lambda p: FullDisk(p, room=4000))
    for k in range(200):
        wall.t += 1
        rec.message("/log", String(data="x" * 40 + str(k)), b"%d" % k, published=wall.t)
        if k % 10 == 9:
            rec.out.sync()
    rec.message("/log", String(data="after"), b"after")   # ignored, never raises
    rec.close()
    assert rec.stats()["write_errors"] == 1 and rec.stats()["failed"]
    assert "No space left on device" in caplog.text
    got = read_file(path)
    assert 10 <= len(got.messages["/log"]) < 200 and got.ends


def test_recordings_rotate_and_keep_only_the_newest_files(tmp_path):
    wall = Wall()
    path = tmp_path / "s.mcap"
    rec = recorder(path, "surface", {"/log": "out"}, wall, opts={"max_bytes": 3000, "keep": 2},
                   compression="none")
    for k in range(300):
        wall.t += 1
        rec.message("/log", String(data="y" * 50), b"%d" % k, published=wall.t)
        if k % 20 == 19:
            rec.out.sync()
    rec.close()
    files = sorted(tmp_path.glob("s*.mcap"))
    assert len(files) == 2 and path not in files            # the oldest went
    assert all(f.stat().st_size < 3000 + 4000 for f in files)
    merged = read_recordings(files)                          # each opens alone; one side
    assert len(merged) == 1 and merged[0].side == "surface"


@pytest.mark.parametrize("content, says", [
    (b"", "empty file"),
    (b"PK\x03\x04 a zip file, not a recording", "not an MCAP file"),
    (b"\x89MCAP0\r\n\x01\x05", "cut short before anything was recorded"),
])
def test_bad_input_is_a_clear_error_naming_the_file_and_exit_2(tmp_path, capsys, content, says):
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    assert uwgen_main(["log", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"uwgen log: {path}: " in err and says in err and "Traceback" not in err


def test_an_mcap_file_of_something_else_is_refused(tmp_path, capsys):
    from mcap.writer import Writer
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start("ros2", "someone")
        ch = w.register_channel("/x", "json", 0)
        w.add_message(ch, 1, b"{}", 1)
        w.finish()
    assert uwgen_main(["log", str(path)]) == 2
    assert "not a uwgen bridge recording" in capsys.readouterr().err


def test_a_missing_file_is_exit_2(tmp_path, capsys):
    assert uwgen_main(["log", str(tmp_path / "nope.mcap")]) == 2
    assert "nope.mcap: cannot read" in capsys.readouterr().err


def test_log_draws_the_plots(tmp_path):
    s, v = two_sides(tmp_path, n=6, lose={1})
    png = tmp_path / "link.png"
    assert uwgen_main(["log", str(s), str(v), "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_a_recording_that_cannot_be_created_is_refused_before_the_bridge_starts(tmp_path):
    from uwgen.bridge.plan import PlanError
    from uwgen.bridge.recorder import recorder_for
    plan = SimpleNamespace(network="net", side="surface", outgoing_topics=[], incoming_topics=[])
    options = SimpleNamespace(record=tmp_path / "no" / "such" / "dir" / "x.mcap",
                              record_max_bytes=1 << 20, record_keep=2, link=LINK)
    with pytest.raises(PlanError, match=r"cannot record to .*x\.mcap: No such file"):
        recorder_for(plan, options)
    assert recorder_for(plan, SimpleNamespace(record=None)) is None


def test_status_snapshots_are_recorded_at_most_every_few_seconds_and_always_the_final_one(tmp_path):
    from uwgen.bridge.recorder import STATUS_EVERY
    wall = Wall()
    rec = recorder(tmp_path / "s.mcap", "surface", {}, wall)
    for k in range(10):                       # a timer every second
        rec.status({"n": k})
        wall.t += 1.0
    rec.status({"n": "final"}, final=True)
    rec.close()
    got = [s["n"] for _t, s in read_file(tmp_path / "s.mcap").statuses]
    assert got == [k for k in range(10) if k % int(STATUS_EVERY) == 0] + ["final"]


KILLED_WRITER = """
import sys, time
from pathlib import Path
from types import SimpleNamespace
from std_msgs.msg import String
from uwgen.bridge.recorder import BridgeRecorder, RecordOptions
rec = BridgeRecorder(RecordOptions(Path(sys.argv[1])), network="net", side="surface",
                     link_config=SimpleNamespace(max_read_length=64, period=0.2), topics={"/log": "out"})
rec.topic("/log", String)
start, k = time.monotonic(), 0
while True:
    rec.message("/log", String(data=f"line {k}"), b"%d" % k)
    rec.packet(0.0, "tx", b"%d" % k, "sent")
    k += 1
    if k == 60:
        print("written", flush=True)
    time.sleep(0.05)
"""


def test_a_recording_of_a_killed_process_is_read_up_to_its_last_complete_chunk(tmp_path, capsys):
    import signal
    import subprocess
    import sys
    path = tmp_path / "killed.mcap"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(path)], stdout=subprocess.PIPE,
                            text=True, env=env)
    try:
        assert proc.stdout.readline().strip() == "written"      # 3 s: a few chunks ended
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    got = read_file(path)
    lines = [m.data for m in got.messages["/log"]]
    assert len(lines) >= 20 and len(got.packets) == len(lines)
    assert got.ends and str(path) in got.ends[0]
    assert uwgen_main(["log", str(path)]) == 0
    out = capsys.readouterr().out
    assert "killed.mcap" in out and ("cut short" in out or "without its summary" in out)


def test_service_round_trips_come_from_the_calling_sides_recording(tmp_path):
    wall = Wall()
    rec = recorder(tmp_path / "s.mcap", "surface", {}, wall)
    rec.call("/set_pen", wall.t, wall.t + 0.9, True)
    rec.call("/set_pen", wall.t + 5, wall.t + 17, False)           # timed out: no round trip
    rec.call("/set_pen", wall.t + 20, wall.t + 21.5, True)
    rec.status({"services": {"/set_pen": {"role": "client", "local_calls": 3, "responses": 2,
                                          "link": {}}}}, final=True)
    rec.close()
    row = summarise([read_file(tmp_path / "s.mcap")]).services[0]
    assert (row.name, row.calls, row.ok, row.failed) == ("/set_pen", 3, 2, 1)
    assert [round(x, 3) for x in row.rtts] == [0.9, 1.5]
