"""`uwgen emulate -m MANIFEST`: nodes named after the manifest's sides, with its ports and links."""
from __future__ import annotations

import socket
import textwrap

import pytest

from uwgen.cli import main
from uwgen.commands import emulate
from uwgen.emulator import BROADCAST, Emulator, EmulatorCore, NodeSpec
from uwgen.emulator.from_manifest import scenario_from_manifest

from .helpers import ROOT, SCENARIOS, connect, recv_exactly

DEMO = ROOT / "msg_samples" / "uwgen.yaml"


def parse(*argv: str):
    from uwgen.cli import build_parser
    return build_parser("emulate").parse_args(["emulate", *argv])


def manifest(tmp_path, sides: str, name: str = "uwgen.yaml"):
    path = tmp_path / name
    path.write_text("network: test\nsides:\n" + textwrap.indent(textwrap.dedent(sides), "  "))
    return path


def test_the_demo_manifest_gives_its_sides_ports_and_links():
    scen = emulate.build_scenario(parse("-m", str(DEMO)))
    assert scen.names() == ["surface", "vehicle"]
    assert [n.port for n in scen.nodes] == [4000, 4001]
    assert [scen.period_of(n) for n in scen.names()] == [0.2, 0.2]
    assert [scen.max_read_length_of(n) for n in scen.names()] == [64, 64]
    assert scen.dest_of("surface") == "vehicle" and scen.dest_of("vehicle") == "surface"


def test_a_scenario_file_adds_physics_but_the_manifest_keeps_ports(tmp_path):
    path = manifest(tmp_path, """\
        surface: {port: 4100, link: {max_read_length: 32, period: 0.5}}
        vehicle: {port: 4101}
        """)
    physics = tmp_path / "physics.yaml"
    physics.write_text(textwrap.dedent("""\
        seed: 7
        snr: {wind: 5}
        nodes:
          - name: vehicle
            waypoints: [[0, 200, 0, 0], [10, 1200, 0, 0]]
        """))
    scen = emulate.build_scenario(parse("-m", str(path), str(physics), "--distance", "700"))
    assert scen.seed == 7 and scen.snr.wind == 5.0
    assert [n.port for n in scen.nodes] == [4100, 4101]
    assert scen.period_of("surface") == 0.5 and scen.max_read_length_of("surface") == 32
    assert scen.period_of("vehicle") == 1.0          # the manifest's default link
    assert scen.position_at("vehicle", 2.5) == (450.0, 0.0, 0.0)      # its waypoints
    assert scen.position_at("surface", 0.0) == (0.0, 0.0, 0.0)


def test_the_two_nodes_scenario_agrees_with_the_demo_manifest():
    scen = emulate.build_scenario(parse("-m", str(DEMO), str(SCENARIOS / "two-nodes.yaml")))
    assert [n.port for n in scen.nodes] == [4000, 4001]
    assert scen.distance("surface", "vehicle") == 1500.0


def test_more_than_two_sides_broadcast(tmp_path):
    path = manifest(tmp_path, """\
        surface: {port: 4200}
        auv1: {port: 4201}
        auv2: {port: 4202}
        """)
    scen = scenario_from_manifest(path, spacing=300.0)
    assert scen.names() == ["surface", "auv1", "auv2"]
    assert {scen.dest_of(n) for n in scen.names()} == {BROADCAST}
    assert scen.distance("surface", "auv2") == 600.0


@pytest.mark.parametrize("sides, physics, message", [
    ("a: {port: 4300}\n", None, "at least 2"),
    ("a: {port: 4300}\nb: {port: 4301, host: 10.0.0.7}\n", None, "serves 127.0.0.1 only"),
    ("a: {port: 4300}\nb: {port: 4300}\n", None, "already used by side 'a'"),
    ("a: {port: 4300}\nb: {port: 4301}\n", "nodes: [{name: a}, {name: c}]\n", "c is not a side"),
    ("a: {port: 4300}\nb: {port: 4301}\n", "nodes: [{name: a, port: 5000}, {name: b}]\n",
     "leave port to the manifest"),
    ("a: {port: 4300}\nb: {port: 4301}\n", "nodes: [{name: a, period: 3}, {name: b}]\n",
     "leave period to the manifest"),
])
def test_contradictions_and_bad_manifests_exit_2_with_a_message(tmp_path, capsys, sides,
                                                                physics, message):
    argv = ["emulate", "-m", str(manifest(tmp_path, sides))]
    if physics:
        (tmp_path / "p.yaml").write_text(physics)
        argv.append(str(tmp_path / "p.yaml"))
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_a_contradiction_is_reported_at_its_line_in_the_scenario_file(tmp_path, capsys):
    path = manifest(tmp_path, "a: {port: 4300}\nb: {port: 4301}\n")
    physics = tmp_path / "p.yaml"
    physics.write_text("seed: 2\nnodes:\n  - name: a\n    port: 5000\n")
    assert main(["emulate", "-m", str(path), str(physics)]) == 2
    assert f"{physics}:4:11: node a: port 5000 contradicts the manifest (4300)" in \
        capsys.readouterr().err


def test_a_manifest_error_keeps_its_line_and_column(tmp_path, capsys):
    path = manifest(tmp_path, "a: {port: 99999}\nb: {port: 4301}\n")
    assert main(["emulate", "-m", str(path)]) == 2
    assert f"{path}:3:" in capsys.readouterr().err


@pytest.mark.parametrize("flag", [["--ports", "0", "0"], ["--nodes", "2"], ["--period", "1"],
                                  ["--max-read-length", "10"]])
def test_node_and_link_flags_are_refused_with_a_manifest(flag, capsys):
    assert main(["emulate", "-m", str(DEMO), *flag]) == 2
    assert "manifest" in capsys.readouterr().err


def test_bytes_cross_between_the_sides_named_in_the_manifest(tmp_path):
    # The manifest's ports, but free ones: the emulator serves exactly what it says.
    ports = []
    for _ in range(2):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            ports.append(s.getsockname()[1])
    path = manifest(tmp_path, f"""\
        ground: {{port: {ports[0]}, link: {{period: 0.02}}}}
        rov: {{port: {ports[1]}, link: {{period: 0.02}}}}
        """)
    scen = emulate.build_scenario(parse("-m", str(path), "--distance", "30", "--bitrate",
                                        "200000"))
    with Emulator(scen) as emu:
        assert emu.ports() == {"ground": ports[0], "rov": ports[1]}
        with connect(ports[0]) as ground, connect(ports[1]) as rov:
            ground.sendall(b"hello rov")
            assert recv_exactly(rov, 9) == b"hello rov"


def test_a_broadcast_reaches_every_other_node_and_each_counts_its_own_losses():
    from uwgen.emulator import Scenario
    scen = Scenario(nodes=[NodeSpec("s", dest=BROADCAST), NodeSpec("a", position=(300, 0, 0)),
                           NodeSpec("b", position=(0, 300, 0)),
                           NodeSpec("c", position=(0, 0, 100000), dest="s")],
                    period=0.2, listen_jitter=0.0)
    core = EmulatorCore(scen)
    for n in ("a", "b", "c"):
        core.client_attached(n, 0.0)
    core.client_data("s", 0.0, b"to all")
    out = core.run_until_idle()
    assert sorted(d.node for d in out) == ["a", "b", "c"]
    assert all(d.data == b"to all" and d.source == "s" for d in out)
