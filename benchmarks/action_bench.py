#!/usr/bin/env python3
"""Action benchmark: bytes one Fibonacci goal puts on the link, uwgen (wire format 13)
against the ROS 2 action protocol's own messages serialized by rclpy (CDR), same run.

    .venv/bin/python benchmarks/action_bench.py [--order N] [--feedback K]

A goal of `order` N with K feedback messages and its result, plus (second table) a goal
that is cancelled. The ROS 2 column counts what rmw would carry for the same exchange:
send_goal request and response, K feedback messages, get_result request and response,
and the status array published at each transition (accepted, executing, terminal; each
lists the goal with its 16-byte UUID and stamp). Frames add framing.OVERHEAD bytes to
every payload in both columns.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from action_msgs.msg import GoalInfo, GoalStatus, GoalStatusArray
from action_msgs.srv import CancelGoal
from rclpy.serialization import serialize_message
from test_msgs.action import Fibonacci
from unique_identifier_msgs.msg import UUID

from uwgen.codegen import generate
from uwgen.runtime.wire.framing import OVERHEAD as FRAME_OVERHEAD
from uwgen.runtime.wire.table import ACCEPTED, CANCELED, CANCELING, SUCCEEDED

MANIFEST = """\
network: bench
sides:
  surface: {port: 4000}
  vehicle: {port: 4001}
actions:
  - {name: /fibonacci, id: 9, type: test_msgs/action/Fibonacci, server: vehicle}
"""


def fibonacci(n: int) -> list[int]:
    seq = [0, 1]
    while len(seq) < n + 1:
        seq.append(seq[-1] + seq[-2])
    return seq


def build_codec():
    root = Path(tempfile.mkdtemp(prefix="uwgen_action_bench_"))
    (root / "pkg" / "msg").mkdir(parents=True)
    (root / "pkg" / "msg" / "Unused.msg").write_text("int8 x\n")
    (root / "uwgen.yaml").write_text(MANIFEST)
    return generate(root / "gen", "uwgen_action_bench", folders=[root],
                    manifest=root / "uwgen.yaml").ACTIONS[9]


def ros_exchange(order: int, feedback: int, cancelled: bool) -> list[tuple[str, int]]:
    impl = Fibonacci.Impl
    uuid = UUID(uuid=list(range(16)))
    info = GoalInfo(goal_id=uuid)
    seq = fibonacci(order)
    rows = [("send_goal request", impl.SendGoalService.Request(goal_id=uuid, goal=Fibonacci.Goal(order=order))),
            ("send_goal response", impl.SendGoalService.Response(accepted=True))]
    statuses = [GoalStatus.STATUS_ACCEPTED, GoalStatus.STATUS_EXECUTING]
    for k in range(feedback):
        rows.append((f"feedback {k + 1}", impl.FeedbackMessage(
            goal_id=uuid, feedback=Fibonacci.Feedback(sequence=seq[:k + 3]))))
    if cancelled:
        rows += [("cancel request", CancelGoal.Request(goal_info=info)),
                 ("cancel response", CancelGoal.Response(goals_canceling=[info]))]
        statuses += [GoalStatus.STATUS_CANCELING, GoalStatus.STATUS_CANCELED]
        result = Fibonacci.Result(sequence=seq[:feedback + 2])
        final = GoalStatus.STATUS_CANCELED
    else:
        statuses.append(GoalStatus.STATUS_SUCCEEDED)
        result = Fibonacci.Result(sequence=seq)
        final = GoalStatus.STATUS_SUCCEEDED
    rows += [("get_result request", impl.GetResultService.Request(goal_id=uuid)),
             ("get_result response", impl.GetResultService.Response(status=final, result=result))]
    for status in statuses:
        rows.append((f"status ({status})", GoalStatusArray(
            status_list=[GoalStatus(goal_info=info, status=status)])))
    return [(name, len(serialize_message(msg))) for name, msg in rows]


def uwgen_exchange(codec, order: int, feedback: int, cancelled: bool) -> list[tuple[str, int]]:
    seq = fibonacci(order)
    h = 7
    rows = [("goal", codec.encode_goal(h, Fibonacci.Goal(order=order))),
            ("answer", codec.encode_answer(h, ACCEPTED))]
    for k in range(feedback):
        rows.append((f"feedback {k + 1}", codec.encode_feedback(h, Fibonacci.Feedback(sequence=seq[:k + 3]))))
    if cancelled:
        rows += [("cancel", codec.encode_cancel(h)), ("cancel answer", codec.encode_answer(h, CANCELING)),
                 ("result", codec.encode_result(h, CANCELED, Fibonacci.Result(sequence=seq[:feedback + 2])))]
    else:
        rows.append(("result", codec.encode_result(h, SUCCEEDED, Fibonacci.Result(sequence=seq))))
    return [(name, len(data)) for name, data in rows]


def table(title: str, ours: list[tuple[str, int]], ros: list[tuple[str, int]]) -> None:
    def total(rows):
        return sum(n for _, n in rows), sum(n + FRAME_OVERHEAD for _, n in rows), len(rows)
    o_pay, o_frame, o_n = total(ours)
    r_pay, r_frame, r_n = total(ros)
    print(f"\n{title}")
    print(f"| {'':24} | {'messages':>8} | {'payload B':>9} | {'framed B':>8} |")
    print(f"|{'-' * 26}|{'-' * 9}:|{'-' * 10}:|{'-' * 9}:|")
    print(f"| {'ROS 2 action (CDR)':24} | {r_n:>8} | {r_pay:>9} | {r_frame:>8} |")
    print(f"| {'uwgen (wire format 13)':24} | {o_n:>8} | {o_pay:>9} | {o_frame:>8} |")
    print(f"| {'uwgen / ROS 2':24} | {o_n / r_n:>8.2f} | {o_pay / r_pay:>9.2f} | {o_frame / r_frame:>8.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--order", type=int, default=8)
    parser.add_argument("--feedback", type=int, default=3)
    args = parser.parse_args()
    codec = build_codec()
    for cancelled in (False, True):
        what = "cancelled after" if cancelled else "with"
        table(f"Fibonacci order {args.order}, {what} {args.feedback} feedback",
              uwgen_exchange(codec, args.order, args.feedback, cancelled),
              ros_exchange(args.order, args.feedback, cancelled))
    print("\nper payload (uwgen):")
    for name, n in uwgen_exchange(codec, args.order, args.feedback, False):
        print(f"  {name:12} {n:3} B")


if __name__ == "__main__":
    main()
