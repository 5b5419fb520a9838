"""Commands that cannot lie, with real `uwgen bridge` processes over the emulator
(docs/seams.md section 8; benchmarks/truth_processes.py runs the network, truth_bench.py
--processes the whole series): a call and a goal held back 10 s on the request path are
never executed late and their caller is told so; held on the response path they run once and
the caller's outcome says what ran; a server-side bridge SIGKILLed mid-goal and started again
at once leaves no goal unsupervised and the caller gets the real outcome."""
from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest
from ros_domains import next_domain

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from truth_processes import Network, delay_cell, kill_cell  # noqa: E402

pytestmark = [pytest.mark.timeout(400)]


@pytest.mark.slow(seconds=55)
def test_real_bridges_never_run_a_held_command_late_and_tell_the_caller_what_ran(tmp_path):
    with Network(tmp_path, sealed=False, domains=(next_domain(), next_domain())) as net:
        net.ready()
        held = delay_cell(net, 1, 10.0, "request", settle=8.0)
        answered = delay_cell(net, 2, 10.0, "response", settle=8.0)
        tail = net.tail()
    # request path: neither ran (refused stale when released), the caller was told so
    assert (held.call_ran, held.goal_ran) == ([], []), tail
    assert (held.call_told, held.goal_told) == ("no response", "rejected"), tail
    assert held.learnt == {"not_run": 1}, (held, tail)
    # response path: both ran once in time; the goal's caller gets its result, the call's
    # bridge learns it ran
    assert (len(answered.call_ran), len(answered.goal_ran)) == (1, 1), tail
    assert answered.goal_told == "succeeded" and answered.learnt == {"ran_after_timeout": 1}, tail
    for cell in (held, answered):
        assert cell.late() == 0 and cell.double() == 0 and cell.matches(), (cell, tail)


@pytest.mark.slow(seconds=13)
def test_a_server_side_bridge_killed_mid_goal_and_started_at_once_leaves_nothing_unwatched(tmp_path):
    with Network(tmp_path, sealed=True, domains=(next_domain(), next_domain()),
                 goal_seconds=6.0) as net:
        net.ready()
        got = kill_cell(net, 3, down=0.0)
        tail = net.tail()

        def adopted() -> dict:       # the status file is written now and then: wait for it
            return net.status("vehicle").get("actions", {}).get("/fib", {})
        deadline = time.monotonic() + 15.0
        while (time.monotonic() < deadline and adopted().get("orphans_adopted", 0)
               + adopted().get("orphans_finished", 0) == 0):
            time.sleep(0.5)
        adopted = adopted()
    assert got["running when killed"] and got["ran"] == 1, (got, tail)
    assert got["told"] == "succeeded" and got["left running"] == 0, (got, tail)
    assert adopted.get("orphans_adopted", 0) + adopted.get("orphans_finished", 0) == 1, adopted
