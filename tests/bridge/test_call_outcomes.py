"""What became of a service call that timed out (uwgen.bridge.outcomes): the calling side asks,
the serving side remembers what it answered, and the answer is logged and counted."""
from __future__ import annotations

from test_msgs.srv import BasicTypes

from uwgen.bridge.outcomes import bare, query

from .fakes import wait_for
from .test_node import SLOW, pair, served_client  # noqa: F401  (pair: the fixture)


def lose(link, kind: int, count: int = 1000, while_=lambda: True) -> list:
    """`link` loses its next `count` payloads of `kind` that carry fields (not outcome items),
    while `while_()` holds."""
    lost, offer = [], link.offer

    def lossy(key, payload, *args, **kw):
        if payload[0] == kind and bare(payload) is None and len(lost) < count and while_():
            lost.append(payload)
            return True
        return offer(key, payload, *args, **kw)
    link.offer = lossy
    return lost


def test_outcome_items_are_the_head_and_nothing_after():
    assert query(2, 21, 300) == bytes([0x02, 0x15, 0x19, 0x01, 0x2C])
    assert bare(query(3, 200, 7)) == (3, 200, 7)
    assert bare(bytes([0x02, 0x15, 0x07, 0x00])) is None          # a request with a field
    assert bare(b"") is None and bare(bytes([0x02, 0x15, 0x1C])) is None   # cut short


def test_a_call_whose_response_was_lost_is_learnt_to_have_run(pair, capfd):  # noqa: F811
    _, _, bridges, links = pair
    client = served_client(pair, SLOW)
    sb = bridges["surface"]
    # every response (copies too) lost until the call has timed out on the calling side
    lost = lose(links.links["vehicle"], 3, while_=lambda: sb.service_counters[SLOW.id].timeouts == 0)
    future = client.call_async(BasicTypes.Request(int32_value=4))
    wait_for(lambda: sb.service_counters[SLOW.id].ran_after_timeout == 1,
             what="the call learnt to have run")
    assert lost and not future.done()
    assert sb.service_counters[SLOW.id].timeouts == 1
    served = bridges["vehicle"].service_counters[SLOW.id]
    assert served.outcome_answers + served.repeated_replies >= 1 and served.replies == 1
    # the warning follows the count on the executor's thread: a loaded machine may not have
    # written it yet when the count is seen
    err: list[str] = []

    def warned() -> bool:
        err.append(capfd.readouterr().err)
        return "but it RAN on the server side" in "".join(err)
    wait_for(warned, what="the warning written")
    assert sb.status()["services"]["/slow"]["ran_after_timeout"] == 1
    client.remove_pending_request(future)


def test_a_call_whose_request_was_lost_is_learnt_not_to_have_run(pair):  # noqa: F811
    _, _, bridges, links = pair
    client = served_client(pair, SLOW)
    lost = lose(links.links["surface"], 2)          # the request and its copies
    future = client.call_async(BasicTypes.Request(int32_value=4))
    sb = bridges["surface"]
    wait_for(lambda: sb.service_counters[SLOW.id].not_run == 1, what="the call learnt not run")
    assert lost and bridges["vehicle"].service_counters[SLOW.id].requests == 0
    assert sb.service_counters[SLOW.id].ran_after_timeout == 0
    client.remove_pending_request(future)
