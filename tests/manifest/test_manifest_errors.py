"""Every mistake in a manifest is a ManifestError at the manifest's exact file:line:column."""
from __future__ import annotations

import re

import pytest

from uwgen.idl.loader import InterfaceLibrary
from uwgen.idl.model import DefinitionError
from uwgen.manifest.loader import ManifestError, load_manifest

from .helpers import DATA, SAMPLES, SIDES, error_of, library

# One topic in block style. After SIDES (lines 1-4) and a blank line 5, its lines are
# 6 (topics:), 7 (name), 8 (id), 9 (type), 10 (publisher); added keys go on line 11.
TOPIC = """
        topics:
          - name: /a
            id: 3
            type: std_msgs/msg/String
            publisher: surface
"""
SERVICE = """
        services:
          - name: /s
            id: 4
            type: std_srvs/srv/SetBool
            server: vehicle
"""


def topic(**changes: str) -> str:
    """The TOPIC text with some lines replaced (key -> new value text) or added."""
    text = TOPIC
    for key, value in changes.items():
        found = re.search(rf"^ {{10}}(?:- |  ){key}: (.*)$", text, re.MULTILINE)
        if found:
            text = text[: found.start(1)] + value + text[found.end(1):]
        else:
            text += f"            {key}: {value}\n"
    return text


CASES = [
    # (manifest text, line:column, what the message must say)
    pytest.param(SIDES + topic(id="four"), "8:9", "id of topic /a must be an integer, got a string ('four')", id="id-not-int"),
    pytest.param(SIDES + topic(id="true"), "8:9", "id of topic /a must be an integer, got a boolean", id="id-bool"),
    pytest.param(SIDES + topic(id="0"), "8:9", "id of topic /a must be in 1..255, got 0", id="id-zero"),
    pytest.param(SIDES + topic(id="256"), "8:9", "id of topic /a must be in 1..255, got 256", id="id-too-big"),
    pytest.param(SIDES + topic(type="std_msgs/msg/Strin"), "9:11",
                 "unknown type 'std_msgs/msg/Strin' for topic /a: std_msgs/msg/Strin not found; did you mean std_msgs/msg/String? (looked in: " + str(SAMPLES),
                 id="unknown-type"),
    pytest.param(SIDES + topic(type="nope_msgs/Thing"), "9:11", "unknown type 'nope_msgs/Thing'", id="unknown-short-type"),
    pytest.param(SIDES + topic(type="Twist"), "9:11", "type 'Twist' of topic /a is not a type name", id="bare-type"),
    pytest.param(SIDES + topic(type="std_srvs/srv/SetBool"), "9:11",
                 "type 'std_srvs/srv/SetBool' is a service, but topic /a needs a message type", id="topic-with-service-type"),
    pytest.param(SIDES + topic(type="std_srvs/SetBool"), "9:11", "is a service, but topic /a needs a message type",
                 id="topic-with-short-service-type"),
    pytest.param(SIDES + SERVICE.replace("std_srvs/srv/SetBool", "std_msgs/msg/String"), "9:11",
                 "type 'std_msgs/msg/String' is a message, but service /s needs a service type", id="service-with-message-type"),
    pytest.param(SIDES + topic(publisher="boat"), "10:16", "publisher 'boat' of topic /a is not a declared side (sides: surface, vehicle)",
                 id="publisher-not-side"),
    pytest.param(SIDES + SERVICE.replace("server: vehicle", "server: shore"), "10:13",
                 "server 'shore' of service /s is not a declared side", id="server-not-side"),
    pytest.param(SIDES + topic(name="turtle1/cmd_vel"), "7:11", "invalid topic name: 'turtle1/cmd_vel' is not a fully qualified ROS name",
                 id="relative-name"),
    pytest.param(SIDES + topic(name="/1abc"), "7:11", "must not start with a digit", id="name-digit"),
    pytest.param(SIDES + topic(name="/a//b"), "7:11", "must not contain '//'", id="name-double-slash"),
    pytest.param(SIDES + topic(name="/a/"), "7:11", "must not end with '/'", id="name-trailing-slash"),
    pytest.param(SIDES + topic(name="/a-b"), "7:11", "may contain only letters, digits, '_' and '/'", id="name-dash"),
    pytest.param(SIDES + topic(name="5"), "7:11", "topic name must be a string, got an integer", id="name-not-string"),
    pytest.param(SIDES + SERVICE.replace("/s\n", "/s?\n"), "7:11", "invalid service name", id="service-name"),
    pytest.param(SIDES + topic(rate="-1"), "11:11", "rate of topic /a must be > 0 (or null for no limit), got -1", id="negative-rate"),
    pytest.param(SIDES + topic(rate="0"), "11:11", "rate of topic /a must be > 0", id="zero-rate"),
    pytest.param(SIDES + topic(rate="fast"), "11:11", "rate of topic /a must be a number, got a string ('fast')", id="rate-not-number"),
    pytest.param(SIDES + topic(ttl="-0.5"), "11:10", "ttl of topic /a must be > 0 (or null for no limit), got -0.5", id="negative-ttl"),
    pytest.param(SIDES + topic(ttl=".inf"), "11:10", "ttl of topic /a must be a finite number", id="infinite-ttl"),
    pytest.param(SIDES + topic(priority="1.5"), "11:15", "priority of topic /a must be an integer", id="priority-float"),
    pytest.param(SIDES + topic(queue="lifo"), "11:12", "queue of topic /a must be one of latest, fifo; got 'lifo'", id="bad-queue"),
    pytest.param(SIDES + topic(depth="3"), "11:12", "depth of topic /a only applies to queue: fifo", id="depth-with-latest"),
    pytest.param(SIDES + topic(queue="fifo", depth="0"), "12:12", "depth of topic /a must be >= 1, got 0", id="fifo-depth-zero"),
    pytest.param(SIDES + topic(qos="{reliability: sometimes}"), "11:24", "qos reliability must be one of reliable, best_effort",
                 id="bad-reliability"),
    pytest.param(SIDES + topic(qos="{history: 3}"), "11:11", "unknown key 'history' in qos; known keys: reliability, durability, depth",
                 id="qos-unknown-key"),
    pytest.param(SIDES + topic(profile="fast"), "11:14", "profile of topic /a must be one of native, rmw_desert, packed", id="bad-profile"),
    pytest.param(SIDES + topic(publsher="surface"), "11:5", "unknown key 'publsher' in topic /a; did you mean 'publisher'?",
                 id="misspelled-topic-key"),
    pytest.param(SIDES + TOPIC.replace("            publisher: surface\n", ""), "7:5",
                 "topic /a is missing the required key 'publisher'", id="missing-publisher"),
    pytest.param(SIDES + TOPIC.replace("            id: 3\n", ""), "7:5", "topic /a is missing the required key 'id'", id="missing-id"),
    pytest.param(SIDES + SERVICE + "            timeout: 0\n", "11:14", "timeout of service /s must be > 0, got 0", id="zero-timeout"),
    pytest.param(SIDES + TOPIC + "          - {name: /a, id: 5, type: std_msgs/String, publisher: surface}\n", "11:5",
                 "topic /a is declared twice (first at line 7)", id="duplicate-topic-name"),
    pytest.param(SIDES + SERVICE + "          - {name: /s, id: 5, type: std_srvs/Trigger, server: vehicle}\n", "11:5",
                 "service /s is declared twice (first at line 7)", id="duplicate-service-name"),
    pytest.param(SIDES + TOPIC + SERVICE.replace("id: 4", "id: 3"), "14:9",
                 "id 3 of service /s is already used by topic /a (line 8); ids are unique across topics, services and actions",
                 id="duplicate-id"),
    pytest.param(SIDES + "        fragment_id: 3\n" + TOPIC, "5:14", "fragment_id 3 collides with the id of topic /a (line 9)",
                 id="fragment-id-collides"),
    pytest.param(SIDES + "        fragment_id: 300\n", "5:14", "fragment_id must be in 1..255, got 300", id="fragment-id-range"),
    pytest.param(SIDES + topic(id="1") + "          - {name: /r, id: 9, type: std_msgs/String, publisher: surface, profile: rmw_desert}\n",
                 "8:9", "id 1 of topic /a is reserved for rmw_desert's /discovery while any topic or service uses profile rmw_desert (/r at line 11 does)",
                 id="rmw-reserved-id-1"),
    pytest.param(SIDES + "        profile: rmw_desert\n" + SERVICE.replace("id: 4", "id: 2"), "9:9",
                 "id 2 of service /s is reserved for rmw_desert's /discovery_request", id="rmw-reserved-id-2"),
    pytest.param(SIDES + "        profile: rmw_desert\n        fragment_id: 1\n" + TOPIC, "6:14",
                 "fragment_id 1 is reserved for rmw_desert's /discovery", id="rmw-reserved-fragment-id"),
    pytest.param(SIDES + "        schema_id: 3\n" + TOPIC, "5:12", "schema_id 3 collides with the id of topic /a (line 9)",
                 id="schema-id-collides"),
    pytest.param(SIDES + "        schema_id: 0\n", "5:12", "schema_id must be in 1..255, got 0", id="schema-id-range"),
    pytest.param(SIDES + "        fragment_id: 9\n        schema_id: 9\n", "6:12",
                 "schema_id 9 is also the fragment_id; the two reserved ids must differ", id="schema-id-is-fragment-id"),
    pytest.param(SIDES + "        profile: rmw_desert\n        schema_id: 2\n" + TOPIC, "6:12",
                 "schema_id 2 is reserved for rmw_desert's /discovery_request", id="rmw-reserved-schema-id"),
    pytest.param(SIDES + "        schema_period: 0\n", "5:16", "schema_period (seconds; null for none) must be > 0, got 0",
                 id="schema-period-zero"),
    pytest.param(SIDES + "        netwrk: demo\n", "5:1", "unknown key 'netwrk' in the manifest; did you mean 'network'?", id="misspelled-top-key"),
    pytest.param(SIDES + "        colour: red\n", "5:1", "unknown key 'colour' in the manifest; known keys: network, package", id="unknown-top-key"),
    pytest.param(SIDES + "        network: again\n", "5:1", "duplicate key 'network' in the manifest (first at line 1)", id="duplicate-yaml-key"),
    pytest.param(SIDES + "        topics: {name: /a}\n", "5:9", "topics must be a list, got a mapping", id="topics-not-list"),
    pytest.param(SIDES + "        profile: fast\n", "5:10", "profile must be one of native, rmw_desert, packed; got 'fast'", id="bad-network-profile"),
    pytest.param(SIDES + "        package: 2fast\n", "5:10", "package '2fast' must be a valid Python package name", id="bad-package"),
    pytest.param(SIDES + "        defaults: {queue: latest, depth: 4}\n", "5:34", "depth of defaults only applies to queue: fifo",
                 id="defaults-depth-with-latest"),
    pytest.param(SIDES + "        defaults: {ttl: -3}\n", "5:17", "ttl of defaults must be > 0", id="defaults-negative-ttl"),
    pytest.param(SIDES + "        defaults: {timeout: 3}\n", "5:12", "unknown key 'timeout' in defaults", id="defaults-unknown-key"),
    pytest.param("""
        network: Demo-Net
        sides: {a: {port: 1}}
        """, "1:10", "network 'Demo-Net' must be lower case letters", id="bad-network-name"),
    pytest.param("""
        sides: {a: {port: 1}}
        """, "1:1", "the manifest is missing the required key 'network'", id="missing-network"),
    pytest.param("""
        network: demo
        """, "1:1", "the manifest is missing the required key 'sides'", id="missing-sides"),
    pytest.param("""
        network: demo
        sides: [surface, vehicle]
        """, "2:8", "sides must be a mapping, got a list", id="sides-not-mapping"),
    pytest.param("""
        network: demo
        sides: {}
        """, "2:8", "sides must name at least one side", id="no-sides"),
    pytest.param("""
        network: demo
        sides:
          surface: {port: 70000}
        """, "3:19", "port of side 'surface' must be in 1..65535, got 70000", id="port-range"),
    pytest.param("""
        network: demo
        sides:
          surface: {host: 127.0.0.1}
        """, "3:12", "side 'surface' is missing the required key 'port'", id="missing-port"),
    pytest.param("""
        network: demo
        sides:
          surface: {port: 4000}
          vehicle: {port: 4000}
        """, "4:19", "side 'vehicle' uses 127.0.0.1:4000, already used by side 'surface'", id="duplicate-port"),
    pytest.param("""
        network: demo
        sides:
          surface: {port: 4000, host: "not a host!"}
        """, "3:31", "host 'not a host!' of side 'surface' is neither an IP address nor a host name", id="bad-host"),
    pytest.param("""
        network: demo
        sides:
          surface: {port: 4000, link: {max_read_length: 5000}}
        """, "3:49", "max_read_length of side 'surface' must be in 1..4096, got 5000", id="max-read-length"),
    pytest.param("""
        network: demo
        sides:
          surface: {port: 4000, link: {period: 0}}
        """, "3:40", "period of side 'surface' must be > 0, got 0", id="zero-period"),
    pytest.param("""
        network: demo
        sides:
          surface: {port: 4000, link: {perod: 1}}
        """, "3:32", "unknown key 'perod' in link of side 'surface'; did you mean 'period'?", id="misspelled-link-key"),
    pytest.param("""
        network: demo
        sides:
          2nd: {port: 4000}
        """, "3:3", "side name '2nd' must be letters", id="bad-side-name"),
    pytest.param("", "1:1", "empty manifest", id="empty"),
    pytest.param("- just\n- a list\n", "1:1", "the manifest must be a mapping, got a list", id="not-a-mapping"),
    pytest.param("network: demo: x\n", "1:14", "YAML syntax error: mapping values are not allowed here", id="yaml-syntax"),
]


@pytest.mark.parametrize("text, where, fragment", CASES)
def test_manifest_error_is_located_and_explained(tmp_path, text, where, fragment):
    error = error_of(tmp_path, text)
    assert f"{error.where.line}:{error.where.column}" == where, error.message
    assert fragment in error.message


@pytest.mark.parametrize("name, expected", [
    ("syntax_error.yaml", "syntax_error.yaml:4:10: YAML syntax error: expected ',' or '}', but got ':'"),
    ("misspelled_key.yaml", "misspelled_key.yaml:8:5: unknown key 'publsher' in topic /chatter; did you mean 'publisher'?"),
    ("duplicate_id.yaml", "duplicate_id.yaml:12:9: id 9 of service /b is already used by topic /a (line 7)"),
])
def test_broken_manifest_files(name, expected):
    with pytest.raises(ManifestError) as info:
        load_manifest(DATA / name, library())
    assert str(info.value).startswith(f"{DATA}/{expected}")


def test_unreadable_manifest_is_a_manifest_error(tmp_path):
    with pytest.raises(ManifestError, match=r"manifest .*missing.yaml not found"):
        load_manifest(tmp_path / "missing.yaml", library())


def test_a_broken_definition_named_by_the_manifest_reports_the_definition(tmp_path):
    (tmp_path / "defs" / "my_msgs" / "msg").mkdir(parents=True)
    broken = tmp_path / "defs" / "my_msgs" / "msg" / "Broken.msg"
    broken.write_text("int32 ok\nuint8 level 999\n")
    manifest = tmp_path / "uwgen.yaml"
    manifest.write_text("network: n\nsides: {a: {port: 4000}}\ntopics:\n  - {name: /x, id: 3, type: my_msgs/Broken, publisher: a}\n")
    lib = InterfaceLibrary(folders=[tmp_path / "defs"], installed=False)
    with pytest.raises(DefinitionError) as info:
        load_manifest(manifest, lib)
    assert str(info.value.where) == f"{broken}:2:13"
