"""`uwgen emulate`: scenario or flags, counters at exit, the PDR sweep table and plot."""
from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from uwgen import tether
from uwgen.cli import main
from uwgen.commands import emulate

from .helpers import ROOT, SCENARIOS


def parse(*argv: str):
    from uwgen.cli import build_parser
    return build_parser("emulate").parse_args(["emulate", *argv])


def test_flags_build_a_line_of_nodes_each_sending_to_the_next():
    scen = emulate.build_scenario(parse("--nodes", "3", "--ports", "0", "0", "0", "--distance",
                                        "500", "--period", "0.5", "--max-read-length", "32",
                                        "--bitrate", "9600", "--per", "0.1", "--seed", "4",
                                        "--wind", "5"))
    assert scen.names() == ["node1", "node2", "node3"]
    assert scen.distance("node1", "node3") == 1000.0
    assert [scen.dest_of(n) for n in scen.names()] == ["node2", "node3", "node1"]
    assert (scen.period, scen.max_read_length, scen.bitrate, scen.per, scen.seed) == (
        0.5, 32, 9600.0, 0.1, 4)
    assert scen.snr is not None and scen.snr.wind == 5.0


def test_flags_override_a_scenario_file():
    scen = emulate.build_scenario(parse(str(SCENARIOS / "two-nodes.yaml"), "--ports", "0", "0",
                                        "--wind", "10", "--period", "1"))
    assert scen.names() == ["surface", "vehicle"]
    assert [n.port for n in scen.nodes] == [0, 0]
    assert scen.period == 1.0 and scen.snr.wind == 10.0
    assert scen.snr.tx_power_db == 174.5


def test_tdma_flags():
    scen = emulate.build_scenario(parse("--ports", "0", "0", "--tdma", "2", "--guard", "0.1"))
    assert scen.tdma.frame == 2.0 and scen.tdma.guard == 0.1


@pytest.mark.parametrize("argv, message", [
    (["--max-read-length", "5000", "--ports", "0", "0"], "above 4096: DESERT crashes"),
    (["--nodes", "1"], "at least 2"),
    (["--nodes", "3", "--ports", "0", "0"], "2 ports for 3 nodes"),
    (["--wind", "0", "5"], "one value"),
    (["--plot", "x.png"], "--plot needs --pdr-sweep"),
])
def test_bad_arguments_exit_2_with_a_message(argv, message, capsys):
    assert main(["emulate", *argv]) == 2
    assert message in capsys.readouterr().err


def test_bad_scenario_file_reports_file_line_column(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("nodes:\n  - name: a\n  - name: b\n    port: 99999\n")
    assert main(["emulate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:4:" in err and "port must be 0..65535" in err


def test_runs_for_a_duration_and_prints_counters(capsys):
    assert main(["emulate", str(SCENARIOS / "tdma.yaml"), "--ports", "0", "0",
                 "--duration", "0.2"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("surface 127.0.0.1:") and out[1].startswith("vehicle 127.0.0.1:")
    header = out[2].split()
    assert header[0] == "node" and "lost_collision" in header and "max_queue_bytes" in header
    assert out[3].split()[0] == "surface" and out[4].split()[0] == "vehicle"


def test_sigterm_stops_the_emulator_and_prints_counters(tmp_path):
    proc = tether.popen(
        [sys.executable, "-m", "uwgen.cli", "emulate", "--ports", "0", "0", "--period", "0.05"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        first = proc.stdout.readline()
        assert first.startswith("node1 127.0.0.1:")
        proc.stdout.readline()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0
    assert "SIGTERM received, stopping" in err
    assert out.splitlines()[0].split()[0] == "node"


def test_pdr_sweep_prints_the_table_and_saves_the_plot(tmp_path, capsys):
    png = tmp_path / "pdr.png"
    start = time.monotonic()
    assert main(["emulate", "--pdr-sweep", "--wind", "0", "10", "--packets", "100",
                 "--plot", str(png)]) == 0
    assert time.monotonic() - start < 20
    out = capsys.readouterr().out
    assert out.splitlines()[0].split() == ["distance_km", "wind_0", "wind_10"]
    assert "wind 0 m/s: full delivery (>= 99 %) up to" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# -- the default PHY: DESERT's stock scenario's, others by name ---------------------------

REAL_ONE_WAY = {3400.0: 0.91, 3500.0: 0.78, 3600.0: 0.47, 3700.0: 0.18}   # measured on DESERT


def test_the_default_phy_is_desert_stock_and_delivers_as_real_desert_near_its_range():
    from uwgen.emulator.sweep import pdr_at
    scen = emulate.build_scenario(parse("--ports", "0", "0", "--distance", "3500"))
    for distance, real in REAL_ONE_WAY.items():
        got = pdr_at(distance, scen.snr, packets=600, seed=1).pdr
        assert abs(got - real) <= 0.06, (distance, got, real)


def test_other_phys_by_name_and_a_scenario_files_own_is_kept():
    assert emulate.build_scenario(parse("--ports", "0", "0", "--phy", "none")).snr is None
    assert emulate.build_scenario(parse("--ports", "0", "0", "--phy", "thesis")).snr.tx_power_db == 174.5
    own = emulate.build_scenario(parse(str(SCENARIOS / "two-nodes.yaml"), "--ports", "0", "0"))
    assert own.snr.tx_power_db == 174.5                        # the file says so
    stock = emulate.build_scenario(parse(str(SCENARIOS / "two-nodes.yaml"), "--ports", "0", "0",
                                         "--phy", "desert-stock"))
    assert stock.snr.tx_power_db == 150.0


def test_emulate_and_demo_say_the_default_phy_in_their_help():
    for command in ("emulate", "demo"):
        res = subprocess.run([str(Path(sys.executable).parent / "uwgen"), command, "--help"], cwd=ROOT,
                             capture_output=True, text=True, timeout=60)
        text = " ".join(res.stdout.split())
        assert "--phy NAME" in text and "desert-stock" in text and "thesis" in text, command


def test_the_pdr_sweep_of_the_default_phy_fades_where_desert_does():
    res = subprocess.run([str(Path(sys.executable).parent / "uwgen"), "emulate", "--pdr-sweep", "--wind", "0",
                          "--packets", "200"], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    rows = {line.split()[0]: float(line.split()[1]) for line in res.stdout.splitlines()
            if line.split() and line.split()[0][0].isdigit()}
    assert rows["3.00"] >= 0.99 and rows["3.50"] < 0.9 and rows["4.00"] == 0.0, rows
