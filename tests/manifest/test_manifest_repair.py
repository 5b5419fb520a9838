"""`repair:` in a manifest: repair fragments per fragmented message (wire format section 11)."""
from __future__ import annotations

import pytest

from .helpers import SIDES, error_of, load_text

FRAG = "        fragment_id: 250\n"
TOPIC = """
        topics:
          - name: /log
            id: 3
            type: std_msgs/msg/String
            publisher: vehicle
            queue: fifo
            repair: {repair}
"""


def test_repair_is_read_per_topic_and_defaults_to_none(tmp_path):
    m = load_text(tmp_path, SIDES + FRAG + TOPIC.format(repair=2) + """\
          - name: /cmd
            id: 4
            type: std_msgs/msg/String
            publisher: surface
""")
    assert [t.policy.repair for t in m.topics] == [2, 0]


def test_repair_in_defaults_applies_to_every_topic(tmp_path):
    m = load_text(tmp_path, SIDES + FRAG + "        defaults: {repair: 1}\n" + TOPIC.format(repair=3).replace(
        "            repair: 3\n", ""))
    assert m.topics[0].policy.repair == 1


@pytest.mark.parametrize("text, where, fragment", [
    pytest.param(SIDES + FRAG + TOPIC.format(repair=-1), "13:13", "repair of topic /log must be in 0..32, got -1",
                 id="negative"),
    pytest.param(SIDES + FRAG + TOPIC.format(repair="two"), "13:13", "repair of topic /log must be an integer",
                 id="not-int"),
    pytest.param(SIDES + TOPIC.format(repair=2), "12:13",
                 "repair of topic /log needs fragments: set fragment_id", id="no-fragment-id"),
    pytest.param(SIDES + FRAG + TOPIC.format(repair=2) + "            profile: rmw_desert\n", "13:13",
                 "profile rmw_desert messages are never fragmented", id="rmw-desert"),
])
def test_bad_repair_is_located_and_explained(tmp_path, text, where, fragment):
    error = error_of(tmp_path, text)
    assert f"{error.where.line}:{error.where.column}" == where, error.message
    assert fragment in error.message
