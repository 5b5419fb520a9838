"""`reliability:` of a topic on the link (wire-format.md section 15): best effort by default, reliable on
request, never in profile rmw_desert (its nodes read no acknowledgements)."""
from __future__ import annotations

import pytest

from .helpers import SIDES, error_of, load_text

TOPIC = """
        topics:
          - name: /cmd
            id: 4
            type: std_msgs/msg/String
            publisher: surface
"""


def test_topics_are_best_effort_unless_reliable_is_asked(tmp_path):
    m = load_text(tmp_path, SIDES + TOPIC + "            reliability: reliable\n" + """\
          - name: /log
            id: 5
            type: std_msgs/msg/String
            publisher: vehicle
            reliability: best_effort
          - name: /pose
            id: 6
            type: std_msgs/msg/String
            publisher: vehicle
""")
    assert [t.policy.reliable for t in m.topics] == [True, False, False]


@pytest.mark.parametrize("extra, where, fragment", [
    pytest.param("            reliability: reliable\n            profile: rmw_desert\n", "11:18",
                 "profile rmw_desert cannot be reliable", id="rmw-desert"),
    pytest.param("            reliability: sure\n", "11:18", "reliability of topic /cmd", id="unknown"),
])
def test_bad_reliability_is_located_and_explained(tmp_path, extra, where, fragment):
    error = error_of(tmp_path, SIDES + TOPIC + extra)
    assert f"{error.where.line}:{error.where.column}" == where, error.message
    assert fragment in error.message
