"""The `actions:` section: defaults, every key, and file:line:column errors."""
from __future__ import annotations

import pytest

from uwgen.idl.model import ActionDef
from uwgen.manifest.model import LinkPolicy

from .helpers import SIDES, error_of, load_text

# After SIDES (lines 1-4) and a blank line 5: 6 actions:, 7 name, 8 id, 9 type, 10 server.
ACTION = """
        actions:
          - name: /fib
            id: 9
            type: test_msgs/action/Fibonacci
            server: vehicle
"""


def test_an_action_gets_the_documented_defaults(tmp_path):
    m = load_text(tmp_path, SIDES + ACTION)
    (a,) = m.actions
    assert (a.name, a.id, a.type_name, a.server) == ("/fib", 9, "test_msgs/action/Fibonacci", "vehicle")
    assert isinstance(a.type, ActionDef) and a.type.goal.full_name == "test_msgs/action/Fibonacci_Goal"
    assert (a.accept_timeout, a.result_timeout, a.max_goals, a.profile) == (10.0, 600.0, 4, "native")
    assert a.policy == LinkPolicy(queue="fifo", depth=4)
    assert a.feedback == LinkPolicy(rate=0.2, queue="latest", depth=1)
    assert m.entry(9) is a and a.where.line == 7


def test_every_action_key_is_read(tmp_path):
    m = load_text(tmp_path, SIDES + ACTION + """
            accept_timeout: 5
            result_timeout: 90
            max_goals: 2
            priority: 3
            ttl: 40
            feedback: {rate: 1, ttl: 4, priority: 2}
    """)
    a = m.actions[0]
    assert (a.accept_timeout, a.result_timeout, a.max_goals) == (5.0, 90.0, 2)
    assert (a.policy.priority, a.policy.ttl) == (3, 40.0)
    assert a.feedback == LinkPolicy(rate=1.0, queue="latest", depth=1, ttl=4.0, priority=2)


def test_feedback_false_sends_no_feedback(tmp_path):
    assert load_text(tmp_path, SIDES + ACTION + "            feedback: false\n").actions[0].feedback is None


@pytest.mark.parametrize("extra, where, fragment", [
    ("            type2: x\n", "11:5", "unknown key 'type2' in action /fib"),
    ("            max_goals: 13\n", "11:16", "max_goals of action /fib must be in 1..12"),
    ("            feedback: {rate: 0}\n", "11:22", "feedback rate of action /fib must be > 0"),
    ("            feedback: {queue: fifo}\n", "11:16", "unknown key 'queue' in feedback of action /fib"),
    ("            feedback: 3\n", "11:15", "must be a mapping (rate, ttl, priority) or false"),
    ("            profile: rmw_desert\n", "11:14", "actions are carried in profile native only"),
    ("            accept_timeout: -1\n", "11:21", "accept_timeout of action /fib must be > 0"),
])
def test_bad_action_keys_are_located(tmp_path, extra, where, fragment):
    error = error_of(tmp_path, SIDES + ACTION + extra)
    assert f"{error.where.line}:{error.where.column}" == where
    assert fragment in error.message


@pytest.mark.parametrize("type_text, fragment", [
    ("std_msgs/msg/String", "is a message, but action /fib needs an action type"),
    ("std_srvs/SetBool", "is a service, but action /fib needs an action type"),
    ("test_msgs/action/Missing", "unknown type 'test_msgs/action/Missing'"),
    ("test_msgs/action/Fibonacci_Goal", "is not an action"),
    ("not a type", "is not a type name"),
])
def test_action_types_are_checked(tmp_path, type_text, fragment):
    error = error_of(tmp_path, SIDES + ACTION.replace("test_msgs/action/Fibonacci", type_text))
    assert (error.where.line, error.where.column) == (9, 11)
    assert fragment in error.message


def test_action_ids_are_unique_with_topics_and_services(tmp_path):
    error = error_of(tmp_path, SIDES + """
        topics:
          - {name: /t, id: 9, type: std_msgs/msg/String, publisher: surface}
    """ + ACTION)
    assert (error.where.line, error.where.column) == (11, 9)
    assert "id 9 of action /fib is already used by topic /t" in error.message


def test_action_server_must_be_a_side(tmp_path):
    error = error_of(tmp_path, SIDES + ACTION.replace("server: vehicle", "server: boat"))
    assert error.where.line == 10 and "server 'boat' of action /fib is not a declared side" in error.message


THREE_SIDES = SIDES + "          buoy: {port: 4002}\n"


def test_client_sides_share_the_goal_handles():
    from uwgen.manifest.model import handle_range
    sides = ["surface", "vehicle", "buoy"]
    assert handle_range(sides, "buoy", "vehicle") == (0, 11)
    assert handle_range(sides, "surface", "vehicle") == (12, 23)
    assert handle_range(["surface", "vehicle"], "surface", "vehicle") == (0, 23)


def test_max_goals_must_fit_a_client_side_share(tmp_path):
    error = error_of(tmp_path, THREE_SIDES + ACTION + "            max_goals: 12\n")
    assert (error.where.line, error.where.column) == (12, 16)
    assert "max_goals of action /fib must be at most 11 with 2 client sides (12 goal handles each)" \
        in error.message


def test_the_default_max_goals_shrinks_to_fit_many_sides(tmp_path):
    many = SIDES + "".join(f"          s{k}: {{port: {4010 + k}}}\n" for k in range(5))
    assert load_text(tmp_path, many + ACTION).actions[0].max_goals == 3   # 6 clients, 4 handles each
