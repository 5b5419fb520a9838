"""No orphaned goals (uwgen.bridge.orphans): the server-side bridge dies mid-goal without a
word (as SIGKILL leaves it), a new one starts, finds the goal on the local action server's
status topic and adopts it; the caller gets the goal's real outcome."""
from __future__ import annotations

import random
import threading
import time

import pytest
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient
from test_msgs.action import Fibonacci

from uwgen.bridge.orphans import OrphanWatch, goal_uuid, handle_of
from uwgen.codegen import generate

from .fakes import LinkPair, fake_package, wait_for
from .harness import ros_sides, start_bridge
from .test_actions import MANIFEST, counted, fib_codec, fib_server, pair, send_goal  # noqa: F401


def test_a_goal_uuid_names_its_action_and_handle_and_nothing_else_is_ours():
    uuid = goal_uuid(9, 7, random.Random(1))
    assert len(uuid) == 16 and uuid[:5] == b"uwg\x09\x07"
    assert handle_of(uuid, 9) == 7 and handle_of(uuid, 10) is None
    assert handle_of(bytes(16), 9) is None


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
    client = ActionClient(surface.node("op"), Fibonacci, "/fib")
    assert client.wait_for_server(timeout_sec=5.0)
    wait_for(lambda: bridges["vehicle"].action_servers.served[9][1].server_is_ready(),
             what="real server visible")
    goal_handle = send_goal(client, 5)
    assert goal_handle.accepted
    kill(vehicle, bridges["vehicle"])
    return results, goal_handle


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


@pytest.fixture(scope="module")
def patient_fib_codec(tmp_path_factory):
    """/fib with a 4 s accept_timeout: a goal may wait 2 s for the local server's list."""
    root = tmp_path_factory.mktemp("patientacts")
    (root / "pkg" / "msg").mkdir(parents=True)
    (root / "pkg" / "msg" / "Unused.msg").write_text("int8 x\n")
    (root / "uwgen.yaml").write_text(MANIFEST.replace("accept_timeout: 0.5", "accept_timeout: 4"))
    return generate(tmp_path_factory.mktemp("gen"), "uwgen_patientacts", folders=[root],
                    manifest=root / "uwgen.yaml").ACTIONS[9]


def test_a_goal_copy_that_reaches_a_restarted_server_side_bridge_before_the_goal_list_is_not_run_again(
        patient_fib_codec, monkeypatch):
    """The server-side bridge is killed while its goal runs; the goal's copy reaches the new
    bridge before the local server's goal list does (held back here, and the status
    publisher shown unmatched, until the copy has come). The copy is held, not sent; the
    list shows the goal running; the running goal is adopted and the copy dropped: the goal
    runs once and the caller gets its result."""
    package = fake_package([])
    package.ACTIONS = {9: patient_fib_codec}
    links = LinkPair()
    release, held = threading.Event(), []
    status, init = OrphanWatch._status, OrphanWatch.__init__

    def late_status(self, msg):                  # the list comes only once released
        if release.is_set():
            status(self, msg)
        else:
            held.append((self, msg))

    def late_init(self, *args, **kw):
        init(self, *args, **kw)
        count = self.sub.get_publisher_count
        self.sub.get_publisher_count = lambda: count() if release.is_set() else 0

    with ros_sides("surface", "vehicle") as (surface, vehicle):
        bridges = {s.name: start_bridge(s, package, links.factory) for s in (surface, vehicle)}
        results, goal_handle = goal_then_kill(surface, vehicle, bridges, delay=2.5)
        assert results == [5]
        monkeypatch.setattr(OrphanWatch, "_status", late_status)
        monkeypatch.setattr(OrphanWatch, "__init__", late_init)
        again = start_bridge(vehicle, package, links.factory)
        wait_for(lambda: again.action_servers.served[9][1].server_is_ready(),
                 what="real server visible again")
        links.links["vehicle"].inject(links.links["surface"].offered(9)[0])   # the goal's copy
        wait_for(lambda: counted(again)["goal_requests"] == 1, what="the copy")
        time.sleep(0.5)                          # it would have been sent by now
        assert results == [5] and counted(again)["waited"] == 1

        def hand_over():                         # in the bridge's executor, as a status message
            release.set()
            for watch, msg in held:
                status(watch, msg)
        timer = again.create_timer(0.01, lambda: (timer.cancel(), hand_over()),
                                   callback_group=again.wiring.main_group)
        wait_for(lambda: counted(again)["orphans_adopted"] == 1, what="the running goal adopted")
        future = goal_handle.get_result_async()
        wait_for(future.done, timeout=10.0, what="the goal's result")
        assert future.result().status == GoalStatus.STATUS_SUCCEEDED
        assert results == [5]                                  # run once
        status_now = counted(again)
        assert (status_now["duplicate_goals"], status_now["orphans_cancelled"]) == (1, 0)
