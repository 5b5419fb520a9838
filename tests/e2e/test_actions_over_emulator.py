"""ROS 2 actions (test_msgs/action/Fibonacci) between real rclpy action clients and servers,
through both bridges and the emulated acoustic link (wire format 13)."""
from __future__ import annotations

import time

import pytest
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future
from test_msgs.action import Fibonacci

from bridge.fakes import wait_for

from .conftest import build_package, network

ACTION_ID = 9
MANIFEST = """\
network: e2e_actions
package: uwgen_e2e_actions
schema_id: 249
sides:
  surface:
    port: 4000
  vehicle:
    port: 4001
actions:
  - name: /fibonacci
    id: 9
    type: test_msgs/action/Fibonacci
    server: vehicle
    accept_timeout: 2
    result_timeout: 4
    max_goals: 2
    feedback: {rate: 10}
"""


@pytest.fixture(scope="module")
def action_package(tmp_path_factory):
    return build_package(tmp_path_factory.mktemp("e2e_actions"), MANIFEST, "uwgen_e2e_actions")


@pytest.fixture
def net(action_package):
    with network(action_package) as n:
        yield n


def rclpy_sleep(node, seconds: float) -> Future:
    """A future done after `seconds`, for async callbacks that must not block the executor."""
    done = Future()

    def fire():
        timer.cancel()
        if not done.done():
            done.set_result(True)
    timer = node.create_timer(seconds, fire)
    return done


class FibonacciServer:
    """The real action server on the vehicle: one number per `step` seconds, with feedback."""

    def __init__(self, node, step: float = 0.1, reject_above: int = 30, abort_at: int | None = None,
                 cancellable: bool = True):
        self.node, self.step, self.reject_above, self.abort_at = node, step, reject_above, abort_at
        self.cancellable = cancellable
        self.goals: list[int] = []
        self.cancels = 0
        self.server = ActionServer(node, Fibonacci, "/fibonacci", self.execute,
                                   goal_callback=self.on_goal, cancel_callback=self.on_cancel)

    def on_goal(self, goal):
        return GoalResponse.REJECT if goal.order > self.reject_above else GoalResponse.ACCEPT

    def on_cancel(self, goal_handle):
        self.cancels += 1
        return CancelResponse.ACCEPT if self.cancellable else CancelResponse.REJECT

    async def execute(self, goal_handle):
        self.goals.append(goal_handle.request.order)
        seq = [0, 1]
        for _ in range(goal_handle.request.order - 1):
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                return Fibonacci.Result(sequence=seq)
            if len(seq) == self.abort_at:
                goal_handle.abort()
                return Fibonacci.Result(sequence=seq)
            seq.append(seq[-1] + seq[-2])
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=seq))
            await rclpy_sleep(self.node, self.step)
        goal_handle.succeed()
        return Fibonacci.Result(sequence=seq)


def ready_client(net, server_expected: bool = True):
    client = ActionClient(net.surface.node("operator"), Fibonacci, "/fibonacci")
    assert client.wait_for_server(timeout_sec=5.0)     # the surface bridge's stand-in
    wait_for(net.connected, what="both links up")
    if server_expected:
        wait_for(lambda: net.bridges["vehicle"].action_servers.served[ACTION_ID][1].server_is_ready(),
                 what="the vehicle bridge sees the real server")
    return client


def send(client, order: int, feedback: list | None = None):
    future = client.send_goal_async(Fibonacci.Goal(order=order),
                                    feedback_callback=(lambda m: feedback.append(list(m.feedback.sequence)))
                                    if feedback is not None else None)
    wait_for(future.done, timeout=20.0, what="the answer to the goal")
    return future.result()


def result_of(goal_handle, timeout: float = 15.0):
    future = goal_handle.get_result_async()
    wait_for(future.done, timeout=timeout, what="the result")
    return future.result()


def counters(net, side: str) -> dict:
    return net.bridges[side].status()["actions"]["/fibonacci"]


def test_goal_accepted_with_feedback_and_result(net):
    real = FibonacciServer(net.vehicle.node("fibonacci_server"))
    client = ready_client(net)
    feedback: list = []
    goal_handle = send(client, 8, feedback)
    assert goal_handle.accepted
    result = result_of(goal_handle)
    assert result.status == GoalStatus.STATUS_SUCCEEDED
    assert list(result.result.sequence) == [0, 1, 1, 2, 3, 5, 8, 13, 21]
    # The status topic never crossed the link: the surface bridge's own action server
    # published the goal's transitions, and the client saw them.
    wait_for(lambda: goal_handle.status == GoalStatus.STATUS_SUCCEEDED, what="local status")
    assert real.goals == [8]
    assert feedback and feedback[-1] == list(result.result.sequence)[:len(feedback[-1])]
    surface, vehicle = counters(net, "surface"), counters(net, "vehicle")
    assert (surface["accepted"], surface["results"], surface["goals_table"]["completed"]) == (1, 1, 1)
    assert surface["feedback"] >= 1 and vehicle["feedback_sent"] >= surface["feedback"]
    assert (vehicle["answers"], vehicle["results_sent"]) == (1, 1)
    # Schema announcements cover the action's id: each side heard the other's fingerprint
    # of id 9, equal to its own, so nothing was refused.
    own = net.package.ACTIONS[ACTION_ID].fingerprint.hex()
    for side in ("surface", "vehicle"):
        schema = net.bridges[side].status()["schema"]
        assert schema["heard"].get(str(ACTION_ID)) == own and schema["refused"] == 0
    # One goal, one answer and one result (plus repeats if an answer was slow): no
    # get_result, no status on the action's channel; feedback went on its own channel. The
    # report naming the result's packet acknowledges it (wire-format 15.6, a command's fate);
    # the client side acknowledges only a copy of it.
    wait_for(lambda: done(net) == 1, what="the result acknowledged")
    surface = counters(net, "surface")
    assert net.bridges["surface"].link.stats()["channels"][ACTION_ID]["sent"] == \
        1 + surface["goal_resends"] + surface["result_acks"]
    vehicle = counters(net, "vehicle")
    assert net.bridges["vehicle"].link.stats()["channels"][ACTION_ID]["sent"] == \
        2 + vehicle["repeated_replies"] + vehicle["results_resent"]


def done(net) -> int:
    """Results the server side knows arrived: acknowledged, or told so by a report."""
    vehicle = counters(net, "vehicle")
    return vehicle["results_acked"] + vehicle["results_told_arrived"]


def test_cancel_crosses_and_the_goal_ends_canceled(net):
    real = FibonacciServer(net.vehicle.node("fibonacci_server"), step=0.3)
    client = ready_client(net)
    feedback: list = []
    goal_handle = send(client, 25, feedback)
    assert goal_handle.accepted
    wait_for(lambda: feedback, what="first feedback")
    cancel = goal_handle.cancel_goal_async()
    wait_for(cancel.done, timeout=10.0, what="the cancel answer")
    assert len(cancel.result().goals_canceling) == 1
    result = result_of(goal_handle)
    assert result.status == GoalStatus.STATUS_CANCELED
    assert real.cancels == 1
    assert len(result.result.sequence) < 26            # stopped early
    assert counters(net, "surface")["cancels"] == 1


def test_a_cancel_the_real_server_refuses_leaves_the_goal_running(net):
    real = FibonacciServer(net.vehicle.node("fibonacci_server"), step=0.2, cancellable=False)
    client = ready_client(net)
    feedback: list = []
    goal_handle = send(client, 8, feedback)
    wait_for(lambda: feedback, what="first feedback")
    cancel = goal_handle.cancel_goal_async()
    wait_for(cancel.done, timeout=10.0, what="the cancel answer")
    assert cancel.result().goals_canceling == [] and real.cancels == 1
    result = result_of(goal_handle)
    assert result.status == GoalStatus.STATUS_SUCCEEDED
    assert list(result.result.sequence) == [0, 1, 1, 2, 3, 5, 8, 13, 21]


def test_goal_rejected_by_the_real_server(net):
    FibonacciServer(net.vehicle.node("fibonacci_server"), reject_above=10)
    client = ready_client(net)
    goal_handle = send(client, 11)
    assert not goal_handle.accepted
    assert counters(net, "surface")["rejected"] == 1
    assert counters(net, "surface")["goals_table"]["outstanding"] == 0   # the handle is free


def test_goal_aborted_by_the_real_server_ends_aborted_with_its_result(net):
    FibonacciServer(net.vehicle.node("fibonacci_server"), abort_at=4)
    client = ready_client(net)
    goal_handle = send(client, 10)
    assert goal_handle.accepted
    result = result_of(goal_handle)
    assert result.status == GoalStatus.STATUS_ABORTED
    assert list(result.result.sequence) == [0, 1, 1, 2]    # the server's own partial result


def test_goal_rejected_when_no_server_runs_on_the_server_side(net):
    client = ready_client(net, server_expected=False)
    goal_handle = send(client, 5)
    assert not goal_handle.accepted
    assert counters(net, "vehicle")["no_server"] == 1


def test_server_gone_during_a_goal_aborts_it(net):
    server_node = net.vehicle.node("fibonacci_server")
    real = FibonacciServer(server_node, step=0.5)
    client = ready_client(net)
    goal_handle = send(client, 20)
    assert goal_handle.accepted
    # The server's process dies: its action server leaves the graph (destroy_node alone
    # would leave the action's entities behind).
    net.vehicle.executor.remove_node(server_node)
    real.server.destroy()
    server_node.destroy_node()
    result = result_of(goal_handle, timeout=10.0)
    assert result.status == GoalStatus.STATUS_ABORTED
    assert counters(net, "vehicle")["server_gone"] == 1
    assert counters(net, "surface")["result_timeouts"] == 0    # reported, not timed out


def test_link_loss_during_a_goal_aborts_it_after_result_timeout(net):
    real = FibonacciServer(net.vehicle.node("fibonacci_server"), step=0.5)
    client = ready_client(net)
    goal_handle = send(client, 20)
    assert goal_handle.accepted
    lost_at = time.monotonic()
    net.emu.stop()                                   # DESERT is gone: nothing crosses any more
    result = result_of(goal_handle, timeout=10.0)
    assert result.status == GoalStatus.STATUS_ABORTED
    assert time.monotonic() - lost_at >= 2.0          # aborted by result_timeout (4 s from accept)
    assert counters(net, "surface")["result_timeouts"] == 1
    # The server side gives the real goal up after the same timeout and cancels it.
    wait_for(lambda: counters(net, "vehicle")["server_timeouts"] == 1, timeout=8.0,
             what="the server side's own timeout")
    wait_for(lambda: real.cancels == 1, what="the real goal cancelled")


def test_bridges_sharing_one_graph_do_not_loop_a_goal(action_package):
    """Both bridges and the real server in one ROS domain: one goal runs once (it ran in a
    loop until the processes were killed before the guard)."""
    with network(action_package, same_domain=True) as net:
        real = FibonacciServer(net.vehicle.node("fibonacci_server"))
        sb, vb = net.bridges["surface"], net.bridges["vehicle"]
        wait_for(lambda: "/fibonacci" in sb.status()["echo_hazards"]
                 and ACTION_ID not in sb.action_standins.servers, what="the stand-in withdrawn")
        client = ActionClient(net.surface.node("operator"), Fibonacci, "/fibonacci")
        assert client.wait_for_server(timeout_sec=5.0)
        goal_handle = send(client, 4)
        assert goal_handle.accepted
        assert result_of(goal_handle).status == GoalStatus.STATUS_SUCCEEDED
        time.sleep(1.0)
        assert real.goals == [4]
        assert vb.status()["actions"]["/fibonacci"]["goal_requests"] == 0
        assert sb.link.stats()["channels"][ACTION_ID]["offered"] == 0


def test_a_result_lost_once_is_sent_again_and_delivered(net):
    real = FibonacciServer(net.vehicle.node("fibonacci_server"))
    link = net.bridges["vehicle"].link
    dropped, offer = [], link.offer

    def lose_first_result(key, payload, *args, **kwargs):
        if key == ACTION_ID and payload[0] == 3 and len(payload) > 4 and not dropped:
            dropped.append(payload)                     # lost on the way
            return True
        return offer(key, payload, *args, **kwargs)
    link.offer = lose_first_result
    client = ready_client(net)
    goal_handle = send(client, 6)
    assert goal_handle.accepted
    result = result_of(goal_handle)
    assert result.status == GoalStatus.STATUS_SUCCEEDED
    assert list(result.result.sequence) == [0, 1, 1, 2, 3, 5, 8] and real.goals == [6]
    assert len(dropped) == 1 and counters(net, "vehicle")["results_resent"] >= 1
    wait_for(lambda: done(net) == 1, what="the result acknowledged (or told arrived)")
