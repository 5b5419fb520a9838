"""What the bridge counts, and the once-per-change log lines about drops.

Counters are plain ints, only ever increased, owned by the executor thread. The status
snapshot is JSON-able; `DropReporter` turns increases of the drop counters between two
snapshots into one log line per entry, so a burst of 500 drops is one line, not 500.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

from uwgen.runtime.link.scheduler import DROP_REASONS


@dataclass
class TopicCounters:
    # outgoing (this side publishes)
    taken: int = 0            # local messages the bridge's subscription received
    superseded: int = 0       # latest-only: taken in one poll with a newer one, never offered
    encode_errors: int = 0    # messages that could not be encoded (counted, logged, not sent)
    offered: int = 0          # payloads the link accepted into its queue
    refused: int = 0          # payloads the link refused (its stats say why)
    # incoming (another side publishes)
    received: int = 0         # payloads that came over the link for this topic
    decode_errors: int = 0    # payloads that did not decode (dropped)
    published: int = 0        # messages published locally
    publish_errors: int = 0   # messages rclpy refused to publish


@dataclass
class ServiceCounters:
    # calling side (stand-in service)
    local_calls: int = 0      # calls made to the stand-in service
    encode_errors: int = 0
    refused: int = 0          # requests the link or the call table refused (no response sent)
    responses: int = 0        # responses returned to local callers
    timeouts: int = 0         # calls that got no response before the manifest timeout
    request_resends: int = 0  # requests sent again (same seq) after an RTO without response
    # what became of timed-out calls (outcomes.py): asked about after the timeout
    outcome_queries: int = 0  # outcome queries sent
    ran_after_timeout: int = 0  # timed out here, but ran there (its response came late)
    not_run: int = 0          # timed out here, and never ran there
    outcome_unknown: int = 0  # timed out here; the server side could not say
    decode_errors: int = 0    # responses (or requests) that did not decode
    # serving side
    requests: int = 0         # requests that came over the link
    duplicate_requests: int = 0  # a request whose seq is already being served (dropped)
    loop_guard: int = 0       # calls (stand-in) or requests (server side) not bridged: another
                              # uwgen bridge in this ROS graph handles the service (loops.py)
    answer_withdrawn: int = 0  # responses that came after the stand-in was withdrawn (loops.py):
                               # their caller cannot be reached (dropped)
    waited: int = 0           # requests that came before the real server was discovered
                              # and waited for it (served once it appeared, or no_server)
    no_server: int = 0        # no real server appeared within the call's timeout (dropped)
    server_timeouts: int = 0  # the real service did not answer within the manifest timeout
    server_errors: int = 0    # the real service's call failed
    replies: int = 0          # responses offered back to the link
    repeated_replies: int = 0  # responses sent again for a copy of an answered request
    outcome_answers: int = 0  # outcome queries answered (the response again, or 'did not run')
    reply_refused: int = 0    # responses the link refused


@dataclass
class ActionCounters:
    # client side (the bridge offers the action to local clients)
    goals: int = 0            # goals local clients sent to the bridge's action server
    refused: int = 0          # goals rejected here: too many in flight, encode error, link refused
    accepted: int = 0         # goals the server side accepted
    rejected: int = 0         # goals the server side rejected
    accept_timeouts: int = 0  # goals with no answer within accept_timeout (then asked about)
    unknown_outcomes: int = 0  # goals the server side never answered about within
                              # result_timeout (rejected locally, a cancel sent: may have run)
    goals_lost_there: int = 0  # accepted goals the server side no longer knows (its bridge
                              # restarted and did not find them): aborted locally
    results: int = 0          # results delivered to local clients
    result_timeouts: int = 0  # goals with no result within result_timeout (aborted locally)
    goal_resends: int = 0     # goals sent again because no answer had come (same handle)
    result_acks: int = 0      # results acknowledged to the server side (copies too)
    cancels: int = 0          # cancel requests sent over the link
    cancel_timeouts: int = 0  # cancels with no answer within accept_timeout (refused locally)
    feedback: int = 0         # feedback messages published to local clients
    late_feedback: int = 0    # feedback for no goal in flight, e.g. sent just before the result
    unknown: int = 0          # answers or results for a handle with no goal lately (dropped)
    late_answers: int = 0     # copies of answers or results for a goal already answered or
                              # finished here: they crossed on the link (counted, not a drop)
    other_sides: int = 0      # payloads for another client side's goals (its handles; ignored)
    decode_errors: int = 0    # payloads of this action that did not decode
    loop_guard: int = 0       # goals not bridged: another uwgen bridge in this graph handles
                              # the action (loops.py)
    # server side (the bridge calls the real action server)
    goal_requests: int = 0    # goals that came over the link
    duplicate_goals: int = 0  # a goal for a handle already in flight, or the copy of a goal
                              # a previous start left running (dropped; orphans.py)
    waited: int = 0           # goals that came before the local server was discovered, or
                              # before its goal list was known (orphans.py), and waited
    no_server: int = 0        # no local action server within accept_timeout / 2: rejected
                              # (once the goal list is known, if it does not show it)
    server_timeouts: int = 0  # the local server did not answer or finish in time
    server_gone: int = 0      # goals aborted because the local server disappeared
    server_errors: int = 0    # the local goal, cancel or result call failed
    answers: int = 0          # answers offered to the link
    repeated_replies: int = 0  # answers or results sent again for a goal that came again
    results_sent: int = 0     # results offered to the link
    results_resent: int = 0   # results sent again: unacknowledged within the RTO, or asked for
    results_acked: int = 0    # results the client side acknowledged
    results_told_arrived: int = 0   # results the link's reports told arrived (fates.py): done
    results_unacked: int = 0  # results never acknowledged within 2 accept_timeouts (given up)
    result_queries: int = 0   # requests for a result not (yet) received: sent by the client
                              # side, received by the server side
    lost_goals: int = 0       # asked about a goal unknown here: answered "no such goal"
    orphans_adopted: int = 0  # goals a previous start of this bridge left running: adopted
    orphans_cancelled: int = 0  # such goals whose handle was busy again: cancelled
    orphans_finished: int = 0  # such goals that finished while no bridge watched: result given
    feedback_sent: int = 0    # feedback offered to the link (latest-only: may be superseded)
    encode_errors: int = 0    # feedback or results that could not be encoded
    reply_refused: int = 0    # answers, results or feedback the link refused


@dataclass
class BridgeCounters:
    """Payloads that belong to no topic or service of this side."""

    unknown_id: int = 0        # an id the manifest does not have
    wrong_direction: int = 0   # e.g. a topic this side publishes arrived from the link
    bad_header: int = 0        # not a CBOR header this bridge can read
    bad_kind: int = 0          # a kind that does not fit the id (topic id with kind 2, ...)
    inbox_overflow: int = 0    # payloads dropped because the executor fell behind
    overheard: int = 0         # payloads for another fleet vehicle's entry: heard, not ours (no drop)
    callback_errors: int = 0   # callbacks that raised (a bug; logged with its traceback)


DROP_FIELDS = {
    "topic": ("encode_errors", "refused", "decode_errors", "publish_errors"),
    "service": ("encode_errors", "refused", "timeouts", "decode_errors", "duplicate_requests",
                "no_server", "server_timeouts", "server_errors", "reply_refused",
                "late", "duplicate", "unknown", "loop_guard", "answer_withdrawn"),
    "action": ("refused", "accept_timeouts", "result_timeouts", "cancel_timeouts", "unknown",
               "decode_errors", "duplicate_goals", "no_server", "server_timeouts", "server_gone",
               "server_errors", "encode_errors", "reply_refused", "loop_guard", "results_unacked",
               "lost_goals"),
    "bridge": tuple(f.name for f in fields(BridgeCounters) if f.name != "overheard"),
    # "superseded" is what a `latest` queue is for (a newer message replaced an older one):
    # it is counted in ~/status and said once, not warned about every report.
    "link": tuple(r for r in DROP_REASONS if r != "superseded"),
}


class DropReporter:
    """Remembers the last drop counts it saw and says what increased since."""

    def __init__(self) -> None:
        self._seen: dict[tuple[str, str, str], int] = {}

    def changes(self, section: str, name: str, counts: dict) -> list[str]:
        parts = []
        for key in DROP_FIELDS.get(section, ()):
            value = counts.get(key, 0)
            if not isinstance(value, int):
                continue
            old = self._seen.get((section, name, key), 0)
            if value > old:
                parts.append(f"{value - old} {key.replace('_', ' ')}")
            self._seen[(section, name, key)] = value
        return parts
