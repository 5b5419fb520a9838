"""Valid manifests load into the model: the demo, the reference, defaults and normalisation."""
from __future__ import annotations

import yaml

from uwgen.manifest.loader import (
    ACTION_KEYS, DEFAULTS_KEYS, FEEDBACK_KEYS, FIFO_DEFAULT_DEPTH, LINK_KEYS, QOS_KEYS, SERVICE_KEYS, SIDE_KEYS, TOP_KEYS, TOPIC_KEYS,
    find_manifest, load_manifest,
)
from uwgen.manifest.model import LinkConfig, LinkPolicy, Qos, Side
from uwgen.idl.model import MessageDef, ServiceDef

from .helpers import SAMPLES, SIDES, library, load_text


def test_demo_manifest_is_exactly_the_contract():
    m = load_manifest(SAMPLES / "uwgen.yaml", library())
    assert (m.network, m.package, m.profile, m.fragment_id) == ("demo", "uwgen_demo", "native", 250)
    link = LinkConfig(max_read_length=64, period=0.2)
    assert {n: (s.host, s.port, s.link) for n, s in m.sides.items()} == {
        "surface": ("127.0.0.1", 4000, link), "vehicle": ("127.0.0.1", 4001, link)}
    topics = [(t.name, t.id, t.type_name, t.publisher, t.policy, t.profile) for t in m.topics]
    assert topics == [
        ("/turtle1/cmd_vel", 4, "geometry_msgs/msg/Twist", "surface", LinkPolicy(5.0, "latest", 1, 2.0, 10), "packed"),
        ("/turtle1/pose", 5, "turtlesim/msg/Pose", "vehicle", LinkPolicy(2.0, "latest", 1, 2.0, 5), "packed"),
        ("/vehicle/battery", 6, "sensor_msgs/msg/BatteryState", "vehicle", LinkPolicy(0.2, "latest", 1, 10.0, 1), "native"),
        ("/vehicle/log", 7, "std_msgs/msg/String", "vehicle", LinkPolicy(None, "fifo", 8, 60.0, 0), "native"),
    ]
    assert [(f.path, f.kind) for f in m.topics[0].fields] == [
        ("linear.x", "quantize"), ("linear.y", "static"), ("linear.z", "quantize"), ("angular.x", "static"),
        ("angular.y", "static"), ("angular.z", "quantize")]
    assert [f.path for f in m.topics[1].fields] == ["x", "y", "theta", "linear_velocity", "angular_velocity"]
    # The battery sends only what the simulated vehicle measures (so, signed, it fits a packet).
    assert {(f.path, f.kind) for f in m.topics[2].fields} == {(p, "omit") for p in (
        "temperature", "charge", "capacity", "design_capacity", "power_supply_health",
        "power_supply_technology", "cell_voltage", "cell_temperature", "location", "serial_number")}
    assert not m.topics[3].fields and all(not s.request_fields for s in m.services)
    services = [(s.name, s.id, s.type_name, s.server, s.timeout) for s in m.services]
    assert services == [
        ("/turtle1/teleport_absolute", 20, "turtlesim/srv/TeleportAbsolute", "vehicle", 10.0),
        ("/vehicle/set_pen", 21, "turtlesim/srv/SetPen", "vehicle", 10.0),
    ]
    assert all(isinstance(t.type, MessageDef) for t in m.topics)
    assert m.topics[1].type.full_name == "turtlesim/msg/Pose"
    assert isinstance(m.services[1].type, ServiceDef) and m.services[1].type.full_name == "turtlesim/srv/SetPen"
    assert m.entry(20).name == "/turtle1/teleport_absolute" and m.entry(99) is None
    cmd_line = (SAMPLES / "uwgen.yaml").read_text().splitlines().index("  - name: /turtle1/cmd_vel") + 1
    assert m.topics[0].where.line == cmd_line and m.source == SAMPLES / "uwgen.yaml"
    assert m.schema_id == 249 and m.schema_period == 600.0


def test_demo_manifest_protects_everything_that_commands_the_vehicle():
    # The secure link in the showcase: the commands are encrypted, the telemetry the operator steers
    # by is signed, the free-text log alone goes in the clear; the key is not in the manifest.
    m = load_manifest(SAMPLES / "uwgen.yaml", library())
    plan = m.security_plan()
    assert plan is not None and plan.key_file == "keys/demo.key"
    assert plan.senders == {"surface": 1, "vehicle": 2}
    commands = [m.entry(4), *m.services, *m.actions]
    assert {e.name for e in commands} == {"/turtle1/cmd_vel", "/turtle1/teleport_absolute",
                                          "/vehicle/set_pen", "/turtle1/rotate_absolute"}
    assert all(plan.modes[e.id] == "encrypt" for e in commands)
    assert plan.modes[5] == plan.modes[6] == "sign"                     # pose, battery
    assert 7 not in plan.modes                                          # /vehicle/log
    assert plan.modes[m.schema_id] == "sign"                            # announcements too


def test_demo_key_is_git_ignored_never_committed():
    import subprocess

    import pytest
    root = SAMPLES.parent
    if not (root / ".git").exists():
        pytest.skip("not a git checkout")
    key = SAMPLES / "keys" / "demo.key"
    ignored = subprocess.run(["git", "check-ignore", "-q", str(key)], cwd=root)
    assert ignored.returncode == 0, f"{key} must be git-ignored"
    tracked = subprocess.run(["git", "ls-files", "msg_samples/keys"], cwd=root, capture_output=True, text=True)
    assert tracked.stdout == ""


def test_reference_manifest_loads():
    m = load_manifest(SAMPLES / "manifest-reference.yaml", library())
    assert m.network == "reference" and len(m.services) == 1
    assert [t.name for t in m.topics if not t.peers] == ["/turtle1/cmd_vel", "/vehicle/log"]
    assert [t.name for t in m.topics if t.peers] == ["/auv1/odometry", "/auv2/odometry"]


def test_reference_manifest_documents_every_key():
    root = yaml.safe_load((SAMPLES / "manifest-reference.yaml").read_text())
    side = next(iter(root["sides"].values()))
    used = {
        "top": set(root),
        "side": set(side),
        "link": set(side["link"]),
        "defaults": set(root["defaults"]),
        "topic": set().union(*(t.keys() for t in root["topics"])),
        "qos": set().union(*(t.get("qos", {}).keys() for t in root["topics"])),
        "service": set().union(*(s.keys() for s in root["services"])),
        "action": set().union(*(a.keys() for a in root["actions"])),
        "feedback": set().union(*(a["feedback"].keys() for a in root["actions"])),
    }
    assert used["top"] == set(TOP_KEYS)
    assert used["side"] == set(SIDE_KEYS)
    assert used["link"] == set(LINK_KEYS)
    assert used["topic"] == set(TOPIC_KEYS)
    assert used["qos"] == set(QOS_KEYS)
    assert used["service"] == set(SERVICE_KEYS)
    assert used["action"] == set(ACTION_KEYS)
    assert used["feedback"] == set(FEEDBACK_KEYS)
    assert used["defaults"] <= set(DEFAULTS_KEYS)
    from uwgen.manifest.security import SECURITY_KEYS
    assert set(root["security"]) == set(SECURITY_KEYS)
    from uwgen.manifest.mac import MAC_KEYS
    text = (SAMPLES / "manifest-reference.yaml").read_text()
    for key in MAC_KEYS:        # turns' keys are set, tdma's documented in comments
        assert f"{key}:" in text
    text = (SAMPLES / "manifest-reference.yaml").read_text()
    for key in DEFAULTS_KEYS:   # documented (in comments) even where not all are set
        assert f"{key}:" in text or f"{key}," in text


def test_defaults_apply_to_topics_that_do_not_set_the_key(tmp_path):
    m = load_text(tmp_path, SIDES + """
        defaults: {priority: 3, ttl: 5, rate: 1, depth: 6, qos: {durability: transient_local}}
        topics:
          - {name: /a, id: 3, type: std_msgs/msg/String, publisher: surface}
          - {name: /b, id: 4, type: std_msgs/msg/String, publisher: surface, priority: 9, queue: fifo}
          - {name: /c, id: 5, type: std_msgs/msg/String, publisher: surface, qos: {depth: 2}}
        """)
    a, b, c = m.topics
    assert a.policy == LinkPolicy(rate=1.0, queue="latest", depth=1, ttl=5.0, priority=3)
    assert b.policy == LinkPolicy(rate=1.0, queue="fifo", depth=6, ttl=5.0, priority=9)
    assert a.qos == Qos(durability="transient_local")
    assert c.qos == Qos(durability="transient_local", depth=2)


def test_unset_keys_take_the_documented_defaults(tmp_path):
    m = load_text(tmp_path, """
        network: tiny
        sides:
          only: {port: 4100}
        topics:
          - {name: /a, id: 3, type: std_msgs/msg/String, publisher: only}
          - {name: /f, id: 4, type: std_msgs/msg/String, publisher: only, queue: fifo}
        services:
          - {name: /s, id: 5, type: std_srvs/srv/Trigger, server: only}
        """)
    assert (m.package, m.profile, m.fragment_id) == ("uwgen_tiny", "native", None)
    assert m.sides["only"] == Side("only", "127.0.0.1", 4100, LinkConfig(64, 1.0), m.sides["only"].where)
    assert m.topics[0].policy == LinkPolicy() and m.topics[0].qos == Qos() and m.topics[0].profile == "native"
    assert m.topics[1].policy == LinkPolicy(queue="fifo", depth=FIFO_DEFAULT_DEPTH)
    assert m.services[0].timeout == 30.0 and m.services[0].policy == LinkPolicy(queue="fifo", depth=4)


def test_short_type_names_are_normalised(tmp_path):
    m = load_text(tmp_path, SIDES + """
        topics:
          - {name: /p, id: 3, type: turtlesim/Pose, publisher: vehicle}
        services:
          - {name: /s, id: 4, type: std_srvs/SetBool, server: vehicle}
        """)
    assert m.topics[0].type_name == "turtlesim/msg/Pose"
    assert m.services[0].type_name == "std_srvs/srv/SetBool"


def test_profiles_per_network_and_per_entry(tmp_path):
    m = load_text(tmp_path, SIDES + """
        profile: rmw_desert
        topics:
          - {name: /a, id: 3, type: std_msgs/String, publisher: surface}
          - {name: /b, id: 4, type: std_msgs/String, publisher: surface, profile: native}
        services:
          - {name: /s, id: 5, type: std_srvs/SetBool, server: vehicle}
        """)
    assert m.profile == "rmw_desert"
    assert [t.profile for t in m.topics] == ["rmw_desert", "native"]
    assert m.services[0].profile == "rmw_desert" and m.uses_rmw_desert()


def test_ids_1_and_2_are_free_without_rmw_desert(tmp_path):
    m = load_text(tmp_path, SIDES + """
        topics:
          - {name: /a, id: 1, type: std_msgs/String, publisher: surface}
          - {name: /b, id: 2, type: std_msgs/String, publisher: surface}
        """)
    assert [t.id for t in m.topics] == [1, 2]


def test_a_topic_and_a_service_may_share_a_name(tmp_path):
    m = load_text(tmp_path, SIDES + """
        topics: [{name: /x, id: 3, type: std_msgs/String, publisher: surface}]
        services: [{name: /x, id: 4, type: std_srvs/Trigger, server: vehicle}]
        """)
    assert m.topics[0].name == m.services[0].name == "/x"


def test_find_manifest_uses_the_uwgen_yaml_convention(tmp_path):
    assert find_manifest(SAMPLES) == SAMPLES / "uwgen.yaml"
    assert find_manifest(tmp_path) is None


def test_schema_announcements_are_off_by_default_and_period_may_be_null(tmp_path):
    m = load_text(tmp_path, SIDES)
    assert m.schema_id is None and m.schema_period == 600.0
    m = load_text(tmp_path, SIDES + "        schema_id: 249\n        schema_period: null\n")
    assert m.schema_id == 249 and m.schema_period is None


def test_strict_priority_only_where_the_manifest_asks(tmp_path):
    m = load_text(tmp_path, SIDES + """
        topics:
          - {name: /alarm, id: 3, type: std_msgs/msg/String, publisher: surface, strict: true}
          - {name: /b, id: 4, type: std_msgs/msg/String, publisher: surface, priority: 9}
        services:
          - {name: /s, id: 5, type: std_srvs/srv/Trigger, server: surface, strict: true}
        """)
    assert [t.policy.strict for t in m.topics] == [True, False]
    assert m.services[0].policy.strict


def test_strict_must_be_a_boolean(tmp_path):
    import pytest
    from uwgen.manifest.loader import ManifestError
    with pytest.raises(ManifestError, match=r"strict of .* must be true or false"):
        load_text(tmp_path, SIDES + """
        topics:
          - {name: /alarm, id: 3, type: std_msgs/msg/String, publisher: surface, strict: 1}
        """)


def test_cut_is_on_unless_a_topic_or_the_defaults_turn_it_off(tmp_path):
    m = load_text(tmp_path, SIDES + """
        defaults: {cut: false}
        topics:
          - {name: /a, id: 3, type: std_msgs/msg/String, publisher: surface, cut: true}
          - {name: /b, id: 4, type: std_msgs/msg/String, publisher: surface}
        """)
    assert [t.policy.cut for t in m.topics] == [True, False]
    assert load_text(tmp_path, SIDES + """
        topics:
          - {name: /b, id: 4, type: std_msgs/msg/String, publisher: surface}
        """).topics[0].policy.cut


def test_cut_is_a_boolean_and_a_topics_key_only(tmp_path):
    import pytest
    from uwgen.manifest.loader import ManifestError
    with pytest.raises(ManifestError, match=r"cut of .* must be true or false"):
        load_text(tmp_path, SIDES + """
        topics:
          - {name: /a, id: 3, type: std_msgs/msg/String, publisher: surface, cut: 2}
        """)
    with pytest.raises(ManifestError, match=r"cut") as e:     # a service has a timeout
        load_text(tmp_path, SIDES + """
        services:
          - {name: /s, id: 5, type: std_srvs/srv/Trigger, server: surface, cut: true}
        """)
    assert e.value.where.line > 0
