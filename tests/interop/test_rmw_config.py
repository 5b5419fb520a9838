"""rmw_desert's id table: written from a manifest, and read back into one that loads."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from conftest import RMW_SAMPLE, SAMPLES
from uwgen.interop.rmw_config import (
    ResolvedType, RmwConfigError, SideSpec, conf_table, export_conf, manifest_from_conf,
    parse_conf, resolve_type_text, resolve_types)
from uwgen.manifest.loader import load_manifest


def test_sample_conf_is_the_export_of_the_sample_manifest(rmw_manifest):
    committed = (RMW_SAMPLE / "ros_allowed_topics.conf").read_text()
    assert export_conf(rmw_manifest).text == committed


def test_export_has_discovery_ids_and_is_in_id_order(rmw_manifest):
    result = export_conf(rmw_manifest)
    data = json.loads(result.text)
    assert list(data) == ["topics"]
    assert data["topics"] == {"/discovery": 1, "/discovery_request": 2, "/turtle1/cmd_vel": 4,
                              "/turtle1/pose": 5, "/turtle1/teleport_absolute": 6}
    assert list(data["topics"].values()) == sorted(data["topics"].values())
    assert result.omitted == []


def test_export_is_deterministic_whatever_the_manifest_order(rmw_manifest):
    shuffled = replace(rmw_manifest, topics=list(reversed(rmw_manifest.topics)))
    assert export_conf(shuffled).text == export_conf(rmw_manifest).text


def test_native_manifest_exports_every_entry_without_discovery(lib):
    demo = load_manifest(SAMPLES / "uwgen.yaml", lib)
    table, omitted = conf_table(demo)
    assert "/discovery" not in table
    assert table == {t.name: t.id for t in (*demo.topics, *demo.services)}
    # The demo's action is uwgen's own (wire format 13): left out, and said so.
    assert omitted == ["/turtle1/rotate_absolute (id 30): an action (wire format 13), which "
                       "rmw_desert nodes do not carry"]


def test_mixed_manifest_leaves_native_entries_out_unless_asked(rmw_manifest):
    mixed = replace(rmw_manifest, topics=[rmw_manifest.topics[0],
                                          replace(rmw_manifest.topics[1], profile="native")])
    table, omitted = conf_table(mixed)
    assert "/turtle1/pose" not in table and "/discovery" in table
    assert len(omitted) == 1 and "/turtle1/pose (id 5)" in omitted[0]
    table, omitted = conf_table(mixed, include_native=True)
    assert table["/turtle1/pose"] == 5 and omitted == []


@pytest.mark.parametrize("text, message, line", [
    ('{"topics": {"/a": 4,}}', "not valid JSON", 1),
    ('{"topics": {\n "/a": 4,\n "/a": 5}}', "appears twice", 2),
    ('{"topics": {\n "/a": 4,\n "/b": 4}}', "already used by /a", 3),
    ('{"topics": {\n "/a": 0}}', "1..255", 2),
    ('{"topics": {\n "/a": 256}}', "1..255", 2),
    ('{"topics": {\n "/a": true}}', "1..255", 2),
    ('{"topics": {\n "/a": 4.0}}', "1..255", 2),
    ('{"topics": {\n "a": 4}}', "start with '/'", 2),
    ('{"topics": {\n "/discovery": 3}}', "must have id 1", 2),
    ('{"topics": {\n "/chatter": 2}}', "reserved for rmw_desert's /discovery_request", 2),
    ('["/a"]', "expected an object", 1),
    ('{"ids": {}}', "expected an object", 1),
])
def test_bad_id_tables_are_refused_where_they_are_wrong(text, message, line):
    with pytest.raises(RmwConfigError, match=message) as info:
        parse_conf(text, "ids.conf")
    assert str(info.value).startswith(f"ids.conf:{line}:")


def test_parse_keeps_file_order_and_accepts_a_table_without_discovery():
    assert list(parse_conf('{"topics": {"/b": 9, "/a": 3}}')) == ["/b", "/a"]


def test_bare_type_names_resolve_when_unambiguous(lib):
    assert resolve_type_text("Twist", lib) == "geometry_msgs/msg/Twist"
    assert resolve_type_text("SetBool", lib) == "std_srvs/srv/SetBool"
    assert resolve_type_text("std_msgs/String", lib) == "std_msgs/msg/String"
    assert resolve_type_text("turtlesim/srv/Spawn", lib) == "turtlesim/srv/Spawn"


def test_ambiguous_or_unknown_type_names_say_why(lib):
    with pytest.raises(ValueError, match="ambiguous: .*geometry_msgs/msg/Pose.*turtlesim/msg/Pose"):
        resolve_type_text("Pose", lib)
    with pytest.raises(ValueError, match="no known"):
        resolve_type_text("NoSuchThing", lib)
    with pytest.raises(ValueError, match="not a known"):
        resolve_type_text("std_msgs/msg/Nope", lib)


def test_every_missing_type_is_listed_at_once(lib):
    names = ["/turtle1/cmd_vel", "/mystery", "/enigma", "/given"]
    with pytest.raises(RmwConfigError) as info:
        resolve_types(names, lib, {"/given": "Pose", "/absent": "Twist"})
    text = str(info.value)
    for expected in ("/mystery: type unknown; give --type /mystery=", "/enigma: type unknown",
                     "/given: --type gives 'Pose'", "ambiguous",
                     "--type /absent: no such name"):
        assert expected in text
    assert "/turtle1/cmd_vel" not in text  # known by convention


def test_types_come_from_options_then_hints_then_convention(lib):
    got = resolve_types(["/turtle1/cmd_vel", "/a", "/b"], lib,
                        {"/a": "std_msgs/msg/Bool", "/turtle1/cmd_vel": "Vector3"},
                        {"/a": "Twist", "/b": "std_srvs/srv/Trigger"})
    assert got["/turtle1/cmd_vel"] == ResolvedType("geometry_msgs/msg/Vector3", "--type")
    assert got["/a"].full_name == "std_msgs/msg/Bool"
    assert got["/b"] == ResolvedType("std_srvs/srv/Trigger", "hints file")
    assert got["/b"].is_service
    with pytest.raises(RmwConfigError, match="/turtle1/cmd_vel: type unknown"):
        resolve_types(["/turtle1/cmd_vel"], lib, {}, builtin=False)


def import_manifest(tmp_path: Path, conf_text: str, lib, side_of: dict[str, str]):
    table = parse_conf(conf_text)
    names = [n for n in table if n not in ("/discovery", "/discovery_request")]
    text = manifest_from_conf(table, types=resolve_types(names, lib, {}), side_of=side_of,
                              sides=[SideSpec("surface", 4000), SideSpec("vehicle", 4001)],
                              network="turtle_rmw")
    path = tmp_path / "uwgen.yaml"
    path.write_text(text)
    return load_manifest(path, lib), text


def test_round_trip_export_import_load_keeps_names_ids_types_and_sides(tmp_path, lib, rmw_manifest):
    side_of = {t.name: t.publisher for t in rmw_manifest.topics}
    side_of.update({s.name: s.server for s in rmw_manifest.services})
    back, text = import_manifest(tmp_path, export_conf(rmw_manifest).text, lib, side_of)

    def summary(m):
        return ([(t.name, t.id, t.type_name, t.publisher, t.profile) for t in m.topics],
                [(s.name, s.id, s.type_name, s.server, s.profile) for s in m.services])

    assert summary(back) == summary(rmw_manifest)
    assert back.profile == "rmw_desert" and back.uses_rmw_desert()
    assert export_conf(back).text == export_conf(rmw_manifest).text
    assert "# by convention for this name: check it" in text


def test_import_needs_a_side_for_every_name(lib):
    table = parse_conf('{"topics": {"/discovery": 1, "/chatter": 4, "/cmd_vel": 5}}')
    types = resolve_types(["/chatter", "/cmd_vel"], lib, {})
    with pytest.raises(RmwConfigError, match="missing: /chatter, /cmd_vel"):
        manifest_from_conf(table, types=types, side_of={}, sides=[SideSpec("a", 4000)],
                           network="n")
    with pytest.raises(RmwConfigError, match="not declared: b"):
        manifest_from_conf(table, types=types, side_of={"/chatter": "a", "/cmd_vel": "b"},
                           sides=[SideSpec("a", 4000)], network="n")


def test_table_without_discovery_gets_a_warning_comment(tmp_path, lib):
    back, text = import_manifest(tmp_path, '{"topics": {"/chatter": 4}}', lib,
                                 {"/chatter": "vehicle"})
    assert "has no /discovery" in text
    assert [(t.name, t.id, t.publisher) for t in back.topics] == [("/chatter", 4, "vehicle")]


def test_imported_manifest_builds_codecs_with_the_table_ids(tmp_path, lib, rmw_manifest):
    from uwgen.codegen import generate
    side_of = {t.name: t.publisher for t in rmw_manifest.topics}
    side_of.update({s.name: s.server for s in rmw_manifest.services})
    conf = export_conf(rmw_manifest).text
    import_manifest(tmp_path, conf, lib, side_of)
    pkg = generate(tmp_path / "gen", "uwgen_imported", manifest=tmp_path / "uwgen.yaml",
                   folders=[SAMPLES], profiles=("native", "rmw_desert"))
    built = {c.name: c.id for c in (*pkg.TOPICS.values(), *pkg.SERVICES.values())}
    table = json.loads(conf)["topics"]
    assert built == {n: i for n, i in table.items() if n not in ("/discovery", "/discovery_request")}
    assert {c.profile for c in pkg.TOPICS.values()} == {"rmw_desert"}
