"""No orphaned goals (uwgen.bridge.orphans): the server-side bridge dies mid-goal without a
word (as SIGKILL leaves it), a new one starts, finds the goal on the local action server's
status topic and adopts it; the caller gets the goal's real outcome."""
from __future__ import annotations

import random
import threading
import time
from contextlib import contextmanager

import pytest
from action_msgs.msg import GoalStatus
from test_msgs.action import Fibonacci

from uwgen.bridge.action_results import REPEAT_WINDOW
from uwgen.bridge.orphans import ARRIVAL_MODULO, OrphanWatch, age_of_copy, goal_uuid, handle_of
from uwgen.codegen import generate

from .fakes import LinkPair, fake_package, wait_for
from .harness import ros_sides, start_bridge
from .test_actions import (MANIFEST, counted, fib_codec, fib_server, op_client, pair,  # noqa: F401
                           send_goal)


def test_a_goal_uuid_names_its_action_and_handle_and_nothing_else_is_ours():
    uuid = goal_uuid(9, 7, random.Random(1))
    assert len(uuid) == 16 and uuid[:5] == b"uwg\x09\x07"
    assert handle_of(uuid, 9) == 7 and handle_of(uuid, 10) is None
    assert handle_of(bytes(16), 9) is None


def test_a_goal_uuid_tells_a_copy_of_its_goal_and_how_long_ago_the_goal_came():
    uuid = goal_uuid(9, 7, random.Random(1), b"\x02\x09\x07\x05", arrived=1_700_000_000.25)
    assert age_of_copy(uuid, b"\x02\x09\x07\x05", 1_700_000_003.0) == pytest.approx(2.75)
    assert age_of_copy(uuid, b"\x02\x09\x07\x06", 1_700_000_003.0) is None   # another goal
    # a clock set back puts the arrival ahead: far outside any window, never "just now"
    assert age_of_copy(uuid, b"\x02\x09\x07\x05", 1_699_999_999.0) > 1e6
    assert age_of_copy(uuid, b"\x02\x09\x07\x05",
                       1_700_000_000.25 + ARRIVAL_MODULO / 1000 + 1.0) == pytest.approx(1.0)


def kill(side, bridge) -> None:
    """The bridge's process is gone: its ROS entities vanish, nothing is said on the link."""
    bridge._closed = True                     # teardown must not close it cleanly either
    bridge.link.mute = True
    side.executor.remove_node(bridge)
    side.nodes.remove(bridge)
    bridge.destroy_node()


def goal_then_kill(surface, vehicle, bridges, delay: float):
    """A goal that runs `delay` s is accepted through the bridges, then the server-side
    bridge is killed: (the goals the real server ran, the caller's goal handle)."""
    results: list = []
    fib_server(vehicle.node("real"), results, delay=delay)
    client = op_client(surface, bridges)
    goal_handle = send_goal(client, 5)
    assert goal_handle.accepted
    kill(vehicle, bridges["vehicle"])
    return results, goal_handle


@contextmanager
def killed_mid_goal(codec, delay: float):
    """Both bridges of a fresh pair serving `codec`, a goal of `delay` s accepted, then the
    server-side bridge killed: (start a new server-side bridge, the link pair, the goals the
    real server ran, the caller's goal handle)."""
    package = fake_package([])
    package.ACTIONS = {9: codec}
    links = LinkPair()
    with ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = {s.name: start_bridge(s, package, links.factory) for s in (surface, vehicle)}
        results, goal_handle = goal_then_kill(surface, vehicle, bridges, delay=delay)
        yield (lambda: start_bridge(vehicle, package, links.factory)), links, results, goal_handle


@pytest.mark.parametrize("down", [0.0, 1.0], ids=["restarted at once", "restarted later"])
def test_a_goal_left_by_a_killed_server_side_bridge_is_adopted_and_its_result_reaches_the_caller(
        pair, fib_codec, down):  # noqa: F811
    surface, vehicle, bridges, links = pair
    results, goal_handle = goal_then_kill(surface, vehicle, bridges, delay=2.0)
    time.sleep(down)
    pkg = fake_package([])
    pkg.ACTIONS = {9: fib_codec}
    again = start_bridge(vehicle, pkg, links.factory)
    future = goal_handle.get_result_async()
    wait_for(future.done, timeout=10.0, what="the goal's result")
    assert future.result().status == GoalStatus.STATUS_SUCCEEDED
    assert list(future.result().result.sequence) == [0, 1]
    assert results == [5]                                  # run once, watched to the end
    assert counted(again)["orphans_adopted"] == 1
    assert counted(bridges["surface"])["goals_lost_there"] == 0


def test_a_goal_that_finished_while_the_server_side_bridge_was_down_reports_its_real_outcome(
        pair, fib_codec):  # noqa: F811
    """The goal succeeds on the vehicle while no server-side bridge runs; the new one finds it
    finished on the local server's status list and, asked by the client side, gives the
    result the server kept: the caller is told succeeded, not aborted or lost."""
    surface, vehicle, bridges, links = pair
    results, goal_handle = goal_then_kill(surface, vehicle, bridges, delay=0.5)
    time.sleep(2.0)                                        # it finishes meanwhile
    assert results == [5]
    pkg = fake_package([])
    pkg.ACTIONS = {9: fib_codec}
    again = start_bridge(vehicle, pkg, links.factory)
    future = goal_handle.get_result_async()
    wait_for(future.done, timeout=15.0, what="the goal's result")
    assert future.result().status == GoalStatus.STATUS_SUCCEEDED
    assert list(future.result().result.sequence) == [0, 1]
    assert results == [5]                                  # run once
    status = counted(again)
    assert (status["orphans_finished"], status["orphans_adopted"], status["lost_goals"]) == (1, 0, 0)
    assert counted(bridges["surface"])["goals_lost_there"] == 0


def fib_codec_with(tmp_path_factory, name: str, accept: float, result: float = 3):
    """/fib of test_actions' manifest with another accept_timeout and result_timeout."""
    root = tmp_path_factory.mktemp(name)
    (root / "pkg" / "msg").mkdir(parents=True)
    (root / "pkg" / "msg" / "Unused.msg").write_text("int8 x\n")
    manifest = MANIFEST.replace("accept_timeout: 0.5", f"accept_timeout: {accept:g}")
    (root / "uwgen.yaml").write_text(manifest.replace("result_timeout: 3", f"result_timeout: {result:g}"))
    return generate(tmp_path_factory.mktemp("gen"), f"uwgen_{name}", folders=[root],
                    manifest=root / "uwgen.yaml").ACTIONS[9]


@pytest.fixture(scope="module")
def patient_fib_codec(tmp_path_factory):
    """/fib with a 4 s accept_timeout: a goal may wait 2 s for the local server's list."""
    return fib_codec_with(tmp_path_factory, "patientacts", accept=4)


def hold_list(monkeypatch, matched: bool = False):
    """From now on a bridge that starts hears its local server's goal list, and (unless
    `matched`) sees the status publisher matched, only once `release(bridge)` is called (in
    the bridge's executor, as a status message comes)."""
    released, held = threading.Event(), []
    status, init = OrphanWatch._status, OrphanWatch.__init__

    def late_status(self, msg):                  # the list comes only once released
        if released.is_set():
            status(self, msg)
        else:
            held.append((self, msg))

    def late_init(self, *args, **kw):
        init(self, *args, **kw)
        if matched:
            return
        count = self.sub.get_publisher_count
        self.sub.get_publisher_count = lambda: count() if released.is_set() else 0

    def hand_over():
        released.set()
        for watch, msg in held:
            status(watch, msg)

    def release(bridge):
        timer = bridge.create_timer(0.01, lambda: (timer.cancel(), hand_over()),
                                    callback_group=bridge.wiring.main_group)

    monkeypatch.setattr(OrphanWatch, "_status", late_status)
    monkeypatch.setattr(OrphanWatch, "__init__", late_init)
    return release


def before_start(again) -> None:
    """The link's judge tells `again` that every goal it takes may have begun before it
    started (its age item reaches back past the start, as a copy's does): the fake link
    carries no age items."""
    started = again.action_servers.watches[9].started
    again.wiring.began_at = lambda payload: started - 1.0


def copy_held(again, links, results: list) -> None:
    """The goal's copy reaches the restarted bridge `again`, whose goal list is held back:
    the copy is held, not sent (results unchanged)."""
    before = list(results)
    wait_for(lambda: again.action_servers.served[9][1].server_is_ready(),
             what="real server visible again")
    links.links["vehicle"].inject(links.links["surface"].offered(9)[0])   # the goal's copy
    wait_for(lambda: counted(again)["goal_requests"] == 1, what="the copy")
    time.sleep(0.5)                              # it would have been sent by now
    assert results == before and counted(again)["waited"] == 1


def adopted_once(again, release, goal_handle, results: list) -> None:
    """The held list comes: the running goal is adopted, the caller gets its result, and it
    ran once."""
    release(again)
    wait_for(lambda: counted(again)["orphans_adopted"] == 1, what="the running goal adopted")
    future = goal_handle.get_result_async()
    wait_for(future.done, timeout=10.0, what="the goal's result")
    assert future.result().status == GoalStatus.STATUS_SUCCEEDED
    assert results == [5]                                  # run once


def test_a_goal_copy_that_reaches_a_restarted_server_side_bridge_before_the_goal_list_is_not_run_again(
        patient_fib_codec, monkeypatch):
    """The server-side bridge is killed while its goal runs; the goal's copy reaches the new
    bridge before the local server's goal list does (held back here, and the status
    publisher shown unmatched, until the copy has come). The copy is held, not sent; the
    list shows the goal running; the running goal is adopted and the copy dropped: the goal
    runs once and the caller gets its result."""
    with killed_mid_goal(patient_fib_codec, delay=2.5) as (restart, links, results, goal_handle):
        assert results == [5]
        release = hold_list(monkeypatch)
        again = restart()
        copy_held(again, links, results)
        adopted_once(again, release, goal_handle, results)
        status_now = counted(again)
        assert (status_now["duplicate_goals"], status_now["orphans_cancelled"]) == (1, 0)


def test_a_goal_copy_is_not_run_again_when_the_goal_list_comes_long_after_its_publisher_matched(
        patient_long_fib_codec, monkeypatch):
    """As above, but the status publisher is seen matched at once and the list comes 2.5 s
    later, past the copy's budget (2 s), as on a loaded machine: the copy is neither sent on
    a guess from the match nor answered; once the list comes the running goal is adopted, it
    ran once and the caller gets its result."""
    with killed_mid_goal(patient_long_fib_codec, delay=5.0) as (restart, links, results, goal_handle):
        release = hold_list(monkeypatch, matched=True)
        again = restart()
        before_start(again)
        copy_held(again, links, results)
        assert again.action_servers.watches[9].sub.get_publisher_count() == 1
        wait_for(lambda: counted(again)["no_server"] == 1, what="the copy's budget over")
        time.sleep(0.5)
        assert results == [5]
        adopted_once(again, release, goal_handle, results)
        codec = patient_long_fib_codec
        rejected = codec.encode_answer(codec.decode_request(links.links["surface"].offered(9)[0])[0], 0)
        assert rejected not in links.links["vehicle"].offered(9)


def test_a_goal_that_began_after_a_restart_runs_without_waiting_for_the_goal_list(
        patient_fib_codec, monkeypatch):
    """A goal the caller sends after the server-side bridge started again cannot copy one
    its predecessor took: it goes to the local server at once, list or no list."""
    with killed_mid_goal(patient_fib_codec, delay=0.2) as (restart, links, results, goal_handle):
        wait_for(lambda: results == [5], what="the first goal")
        hold_list(monkeypatch)
        again = restart()
        again.wiring.began_at = lambda payload: again.wiring.clock.now()   # began just now
        wait_for(lambda: again.action_servers.served[9][1].server_is_ready(),
                 what="real server visible again")
        links.links["vehicle"].inject(patient_fib_codec.encode_goal(6, Fibonacci.Goal(order=7)))
        wait_for(lambda: results == [5, 7], timeout=1.5, what="the new goal run")
        assert counted(again)["waited"] == 0


@pytest.fixture(scope="module")
def patient_long_fib_codec(tmp_path_factory):
    """/fib with a 4 s accept_timeout and a 12 s result_timeout: a goal outlives a restart
    and the 2 s its copy may wait for the local server."""
    return fib_codec_with(tmp_path_factory, "longacts", accept=4, result=12)


def test_a_goal_copy_held_past_its_budget_with_no_server_seen_is_not_answered_rejected(
        patient_long_fib_codec, monkeypatch):
    """The server-side bridge is killed while its goal runs, and the new one sees neither the
    local server nor its goal list while the goal's copy waits out its budget (2 s): the
    server may be one not discovered yet, running the goal, so the copy is dropped unanswered,
    not answered "rejected". Once the server and its list are seen, the running goal is
    adopted and the caller gets its real result; the goal ran once."""
    with killed_mid_goal(patient_long_fib_codec, delay=5.0) as (restart, links, results, goal_handle):
        release = hold_list(monkeypatch)
        again = restart()
        client, seen = again.action_servers.served[9][1], threading.Event()
        ready = client.server_is_ready
        client.server_is_ready = lambda: seen.is_set() and ready()
        copy = links.links["surface"].offered(9)[0]
        links.links["vehicle"].inject(copy)                       # the goal's copy
        wait_for(lambda: counted(again)["no_server"] == 1, what="the copy's budget over")
        rejected = patient_long_fib_codec.encode_answer(patient_long_fib_codec.decode_request(copy)[0], 0)
        assert rejected not in links.links["vehicle"].offered(9)
        seen.set()
        release(again)
        wait_for(lambda: counted(again)["orphans_adopted"] == 1, what="the running goal adopted")
        future = goal_handle.get_result_async()
        wait_for(future.done, timeout=15.0, what="the goal's result")
        assert future.result().status == GoalStatus.STATUS_SUCCEEDED
        assert results == [5] and rejected not in links.links["vehicle"].offered(9)


@pytest.fixture(scope="module")
def slow_fib_codec(tmp_path_factory):
    """/fib with a 20 s accept_timeout (a copy is a repeat for 30 s after its goal came, far
    longer than a restart takes here) and a 30 s result_timeout."""
    return fib_codec_with(tmp_path_factory, "slowacts", accept=20, result=30)


@pytest.fixture
def finished_while_down(slow_fib_codec):
    """A goal accepted through the bridges, the server-side bridge killed, the goal finished
    on the local server meanwhile (its answer and result never left): (start a new
    server-side bridge, the link pair, the goals the real server ran, the caller's goal
    handle)."""
    with killed_mid_goal(slow_fib_codec, delay=0.2) as (restart, links, results, goal_handle):
        time.sleep(1.0)                                    # it finishes meanwhile
        assert results == [5]
        yield restart, links, results, goal_handle


def listed_finished(again, goal: bytes) -> None:
    """The restarted bridge has the local server's list, showing `goal`'s handle finished."""
    wait_for(lambda: goal[2] in again.action_servers.watches[9].finished,
             what="the finished goal listed")


@pytest.mark.parametrize("first", ["list", "copy"])
def test_a_copy_of_a_goal_that_finished_while_the_server_side_bridge_was_down_is_answered_not_run(
        finished_while_down, monkeypatch, first):
    """The goal finished unwatched; the client side, its answer and result lost, copies it.
    The restarted bridge finds it finished in the local server's list (before the copy
    comes, or after: the copy held for the list), within REPEAT_WINDOW accept_timeouts of
    its arrival and with the copy's payload: the copy is answered accepted and gets the
    result the local server kept, and the goal does not run again."""
    start, links, results, goal_handle = finished_while_down
    release = hold_list(monkeypatch) if first == "copy" else None
    again = start()
    if release is None:
        copy = links.links["surface"].offered(9)[0]                       # the goal's copy
        listed_finished(again, copy)
        links.links["vehicle"].inject(copy)
    else:
        copy_held(again, links, results)
        release(again)
    future = goal_handle.get_result_async()
    wait_for(future.done, timeout=15.0, what="the goal's result")
    assert future.result().status == GoalStatus.STATUS_SUCCEEDED
    assert list(future.result().result.sequence) == [0, 1]
    time.sleep(0.5)                                        # a second run would have begun
    assert results == [5]                                  # run once
    status = counted(again)
    assert (status["goal_requests"], status["duplicate_goals"], status["orphans_finished"]) == (1, 1, 1)
    assert status["answers"] >= 1                          # accepted, then the result


@pytest.mark.parametrize("new", ["same goal after the window", "another goal within it"])
def test_a_new_goal_on_the_handle_of_a_goal_that_finished_while_the_bridge_was_down_runs(
        finished_while_down, new):
    """Handles are reused: the same payload on the handle once REPEAT_WINDOW accept_timeouts
    have passed since the finished goal came (the restarted bridge's system clock put that
    far ahead), or another payload at once, is a new goal: it runs."""
    start, links, results, goal_handle = finished_while_down
    again = start()
    copy = links.links["surface"].offered(9)[0]
    if new == "same goal after the window":
        window = REPEAT_WINDOW * again.action_servers.served[9][0].accept_timeout
        again.wiring.wall = lambda: time.time() + window + 1.0
        goal, expected = copy, [5, 5]
    else:
        codec = again.action_servers.served[9][0]
        goal, expected = codec.encode_goal(copy[2], Fibonacci.Goal(order=6)), [5, 6]
    listed_finished(again, copy)
    links.links["vehicle"].inject(goal)
    wait_for(lambda: results == expected, what="the new goal run")
    status = counted(again)
    assert (status["duplicate_goals"], status["orphans_finished"]) == (0, 0)
