"""Scenarios: validation like DESERT's, and YAML errors that point at the line."""
from __future__ import annotations

from pathlib import Path

import pytest

from uwgen.emulator import (NodeSpec, Scenario, ScenarioError, SnrModel, TdmaSpec,
                            load_scenario)

from .helpers import SCENARIOS


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "scenario.yaml"
    p.write_text(text)
    return p


def test_sample_scenarios_load():
    two = load_scenario(SCENARIOS / "two-nodes.yaml")
    assert two.names() == ["surface", "vehicle"]
    assert [n.port for n in two.nodes] == [4000, 4001]
    assert two.distance("surface", "vehicle") == 1500.0
    assert isinstance(two.snr, SnrModel) and two.tdma is None
    tdma = load_scenario(SCENARIOS / "tdma.yaml")
    assert tdma.tdma == TdmaSpec(frame=1.0, guard=0.3, slots=2)
    assert [tdma.slot_of(n) for n in tdma.names()] == [0, 1]


def test_defaults_follow_desert():
    s = Scenario(nodes=[NodeSpec("a"), NodeSpec("b"), NodeSpec("c")])
    assert (s.period, s.max_read_length, s.bitrate, s.sound_speed) == (0.2, 64, 4800.0, 1500.0)
    assert [s.dest_of(n) for n in "abc"] == ["b", "c", "a"]       # a ring by default
    assert s.tx_time(64) == pytest.approx(68 * 8 / 4800)


def test_max_read_length_above_4096_is_refused_as_desert_crashes():
    Scenario(nodes=[NodeSpec("a"), NodeSpec("b")], max_read_length=4096)
    with pytest.raises(ScenarioError, match="above 4096: DESERT crashes"):
        Scenario(nodes=[NodeSpec("a"), NodeSpec("b")], max_read_length=4097)
    with pytest.raises(ScenarioError, match="node b: max_read_length 5000 is above 4096"):
        Scenario(nodes=[NodeSpec("a"), NodeSpec("b", max_read_length=5000)])


@pytest.mark.parametrize("kwargs, message", [
    ({"nodes": [NodeSpec("a")]}, "at least 2 nodes"),
    ({"nodes": [NodeSpec("a"), NodeSpec("a")]}, "unique: a repeated"),
    ({"nodes": [NodeSpec("a", port=4000), NodeSpec("b", port=4000)]}, "ports must be unique"),
    ({"nodes": [NodeSpec("a", dest="z"), NodeSpec("b")]}, "dest 'z' is not a node"),
    ({"nodes": [NodeSpec("a", dest="a"), NodeSpec("b")]}, "not itself"),
    ({"period": 0}, "period must be a positive number"),
    ({"per": 1.5}, r"per must be in \[0, 1\]"),
    ({"max_read_length": 0}, "positive integer"),
    ({"bitrate": -1}, "bitrate"),
])
def test_bad_scenarios_are_refused_with_a_reason(kwargs, message):
    kwargs.setdefault("nodes", [NodeSpec("a"), NodeSpec("b")])
    with pytest.raises(ScenarioError, match=message):
        Scenario(**kwargs)


def test_yaml_error_points_at_the_offending_node(tmp_path):
    p = write(tmp_path, "period: 0.2\nnodes:\n  - name: a\n  - name: b\n    dest: nowhere\n")
    with pytest.raises(ScenarioError) as err:
        load_scenario(p)
    assert str(err.value) == f"{p}:5:11: node b: dest 'nowhere' is not a node (nodes: a, b)"


def test_yaml_unknown_key_is_named_with_its_position(tmp_path):
    p = write(tmp_path, "nodes:\n  - name: a\n  - name: b\nperiode: 0.3\n")
    with pytest.raises(ScenarioError) as err:
        load_scenario(p)
    assert str(err.value).startswith(f"{p}:4:1: unknown setting 'periode'")


def test_yaml_bad_value_reports_the_key(tmp_path):
    p = write(tmp_path, "nodes:\n  - name: a\n  - name: b\nmax_read_length: 8192\n")
    with pytest.raises(ScenarioError) as err:
        load_scenario(p)
    assert str(err.value) == f"{p}:4:18: max_read_length 8192 is above 4096: DESERT crashes with it"


def test_yaml_syntax_error_has_a_position(tmp_path):
    p = write(tmp_path, "nodes: [\n  - name: a\n")
    with pytest.raises(ScenarioError, match=rf"^{p}:\d+:\d+: not valid YAML"):
        load_scenario(p)


def test_yaml_snr_section_is_checked(tmp_path):
    p = write(tmp_path, "snr:\n  wind: -3\nnodes:\n  - name: a\n  - name: b\n")
    with pytest.raises(ScenarioError, match=rf"^{p}:2:3: snr: wind speed must be >= 0"):
        load_scenario(p)


def test_missing_file_is_a_scenario_error(tmp_path):
    with pytest.raises(ScenarioError, match=r"scenario .*nope.yaml not found"):
        load_scenario(tmp_path / "nope.yaml")
