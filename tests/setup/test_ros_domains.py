"""The tests' ROS domain blocks (tests/ros_domains.py): each pytest worker a block of its own,
inside UWGEN_TEST_DOMAINS when it is given."""
from __future__ import annotations

import pytest

import ros_domains


def blocks(monkeypatch, count: int, text: str | None) -> list[range]:
    if text is None:
        monkeypatch.delenv(ros_domains.RANGE_ENV, raising=False)
    else:
        monkeypatch.setenv(ros_domains.RANGE_ENV, text)
    monkeypatch.setenv("PYTEST_XDIST_WORKER_COUNT", str(count))
    out = []
    for i in range(count):
        monkeypatch.setenv("PYTEST_XDIST_WORKER", f"gw{i}")
        out.append(ros_domains.block())
    return out


def test_workers_share_no_domain_and_stay_in_1_to_101(monkeypatch):
    got = blocks(monkeypatch, 3, None)
    ids = [d for b in got for d in b]
    assert len(ids) == len(set(ids)) and min(ids) >= 1 and max(ids) <= 101 and len(got[0]) == 33


def test_a_narrower_range_keeps_every_worker_inside_it(monkeypatch):
    got = blocks(monkeypatch, 3, "1-60")
    ids = [d for b in got for d in b]
    assert len(ids) == len(set(ids)) and min(ids) == 1 and max(ids) <= 60


@pytest.mark.parametrize("text", ["80", "0-50", "50-40", "1-120", "a-b", "5-6"])
def test_a_bad_range_stops_the_run_with_what_is_expected(monkeypatch, text):
    with pytest.raises(SystemExit, match="UWGEN_TEST_DOMAINS"):
        blocks(monkeypatch, 1, text)


def test_a_range_too_small_for_its_workers_stops_the_run_not_loops(monkeypatch):
    with pytest.raises(SystemExit, match="give at least 9"):
        blocks(monkeypatch, 3, "1-8")
    assert [len(b) for b in blocks(monkeypatch, 3, "1-9")] == [3, 3, 3]
