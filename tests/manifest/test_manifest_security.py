"""The manifest's security keys: defaults, overrides, sender ids, and every mistake located."""
from __future__ import annotations

import pytest

from .helpers import error_of, load_text

HEAD = """
        network: demo
        security: {mode: encrypt, key_file: keys/demo.key}
        sides:
          surface: {port: 4000, sender_id: 1}
          vehicle: {port: 4001, sender_id: 2}
        topics:
          - {name: /cmd, id: 4, type: geometry_msgs/msg/Twist, publisher: surface}
          - {name: /log, id: 7, type: std_msgs/msg/String, publisher: vehicle, security: sign}
          - {name: /raw, id: 8, type: std_msgs/msg/String, publisher: vehicle, security: off}
        services:
          - {name: /enable, id: 20, type: std_srvs/srv/SetBool, server: vehicle}
"""


def test_modes_default_to_the_network_and_entries_override(tmp_path):
    m = load_text(tmp_path, HEAD)
    assert {t.name: t.security for t in m.topics} == {"/cmd": "encrypt", "/log": "sign", "/raw": "off"}
    assert m.services[0].security == "encrypt"
    assert m.security.key_file == "keys/demo.key"
    assert m.security.senders == {"surface": 1, "vehicle": 2}
    assert m.security.modes(m.topics) == {4: "encrypt", 7: "sign"}
    assert m.protected()


def test_no_security_block_means_off(tmp_path):
    m = load_text(tmp_path, """
        network: demo
        sides: {surface: {port: 4000}, vehicle: {port: 4001}}
        topics:
          - {name: /cmd, id: 4, type: geometry_msgs/msg/Twist, publisher: surface}
    """)
    assert m.topics[0].security == "off" and not m.protected()


@pytest.mark.parametrize("old,new,where,message", [
    ("mode: encrypt,", "mode: secret,", "2:18", "security mode must be one of off, sign, encrypt; got 'secret'"),
    ("security: sign}", "security: yes}", "8:82", "security of topic /log must be one of off, sign, encrypt"),
    (", key_file: keys/demo.key}", "}", "2:11", "no key is named: add `security: {key_file: PATH}`"),
    ("key_file: keys/demo.key", "key: abc", "2:27", "unknown key 'key' in security"),
    ("{port: 4001, sender_id: 2}", "{port: 4001}", "5:12", "side 'vehicle' needs a sender_id"),
    ("sender_id: 2", "sender_id: 1", "5:36", "sender_id 1 of side 'vehicle' is already the sender_id of side 'surface'"),
    ("sender_id: 2", "sender_id: 16", "5:36", "sender_id of side 'vehicle' must be in 0..15, got 16"),
])
def test_mistakes_are_located(tmp_path, old, new, where, message):
    assert old in HEAD
    err = error_of(tmp_path, HEAD.replace(old, new))
    assert f"{err.where.line}:{err.where.column}" == where
    assert message in err.message


def test_rmw_desert_entries_cannot_be_protected(tmp_path):
    # Without the native service: a native command beside an rmw_desert entry is an error of
    # its own (the mix takes wire format 2 away from it), reported in the same pass.
    topics_only = HEAD.split("        services:")[0]
    text = topics_only.replace("security: off}", "profile: rmw_desert}")
    err = error_of(tmp_path, text)
    assert "topic /raw" in err.message and "rmw_desert" in err.message and "security: off" in err.message
    assert err.where.line == 2              # inherited from the network's mode: points there
    text = topics_only.replace("security: off}", "profile: rmw_desert, security: sign}")
    err = error_of(tmp_path, text)
    assert err.where.line == 9 and "cannot be signed or encrypted" in err.message


def test_rmw_desert_entries_with_security_off_are_fine(tmp_path):
    m = load_text(tmp_path, HEAD.replace("security: off}", "profile: rmw_desert, security: off}")
                  .replace("server: vehicle}", "server: vehicle, profile: rmw_desert, security: off}"))
    assert m.topics[2].profile == "rmw_desert" and m.topics[2].security == "off"


def test_a_native_command_beside_an_rmw_desert_entry_is_refused_where_it_is(tmp_path):
    """An rmw_desert entry keeps the whole link on wire format 1 (no packet time, seal per
    packet or delivery once): a native service there could run late or twice."""
    err = error_of(tmp_path, HEAD.replace("security: off}", "profile: rmw_desert, security: off}"))
    assert (err.where.line, err.where.column) == (11, 5)
    assert "service /enable is a command in profile native" in err.message
    assert "/raw (line 9) is in profile rmw_desert" in err.message and "run twice" in err.message


def test_sender_ids_may_be_left_out_while_security_is_off(tmp_path):
    m = load_text(tmp_path, """
        network: demo
        security: {mode: off}
        sides: {surface: {port: 4000}, vehicle: {port: 4001, sender_id: 3}}
    """)
    assert m.security.senders == {"vehicle": 3} and not m.protected()


def test_schema_announcements_are_signed_when_security_is_on(tmp_path):
    m = load_text(tmp_path, HEAD.replace("network: demo\n", "network: demo\n        schema_id: 249\n"))
    plan = m.security_plan()
    assert plan.modes == {4: "encrypt", 7: "sign", 20: "encrypt", 249: "sign"}
    assert plan.key_file == "keys/demo.key" and plan.senders == {"surface": 1, "vehicle": 2}
    off = load_text(tmp_path, HEAD.replace("mode: encrypt", "mode: off")
                    .replace("security: sign}", "security: off}"))
    assert off.security_plan() is None


ACTIONS = """\
        actions:
          - {name: /go, id: 9, type: test_msgs/action/Fibonacci, server: vehicle}
          - {name: /look, id: 10, type: test_msgs/action/Fibonacci, server: vehicle, security: sign}
          - {name: /idle, id: 11, type: test_msgs/action/Fibonacci, server: vehicle, security: off}
"""


def test_actions_take_the_network_mode_or_their_own_and_join_the_security_plan(tmp_path):
    m = load_text(tmp_path, HEAD + ACTIONS)
    assert {a.name: a.security for a in m.actions} == {"/go": "encrypt", "/look": "sign", "/idle": "off"}
    modes = m.security_plan().modes
    assert (modes[9], modes[10]) == ("encrypt", "sign") and 11 not in modes


def test_a_protected_action_alone_needs_a_key(tmp_path):
    text = """
        network: demo
        security: {mode: off}
        sides:
          surface: {port: 4000, sender_id: 1}
          vehicle: {port: 4001, sender_id: 2}
        actions:
          - {name: /go, id: 9, type: test_msgs/action/Fibonacci, server: vehicle, security: sign}
"""
    err = error_of(tmp_path, text)
    assert "no key is named" in err.message and "actions" in err.message
    assert load_text(tmp_path, text.replace("mode: off}", "mode: off, key_file: k.key}")).protected()


def test_a_bad_action_security_mode_is_located(tmp_path):
    err = error_of(tmp_path, HEAD + ACTIONS.replace("security: sign}", "security: loud}"))
    assert err.where.line == 14                               # /look's line
    assert "security of action /look must be one of off, sign, encrypt" in err.message
