"""Action payloads (wire format 13): the worked bytes of the spec, round trips with rclpy
classes, and refusals of malformed payloads."""
from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_msgs.action import Fibonacci

from uwgen.codegen import generate
from uwgen.runtime.wire.codec import DecodeError, EncodeError
from uwgen.runtime.wire.table import ABORTED, ACCEPTED, CANCEL_REFUSED, CANCELING, REJECTED, SUCCEEDED

SPEC = Path(__file__).resolve().parents[2] / "docs" / "wire-format.md"
MANIFEST = """\
network: acts
sides:
  surface: {port: 4000}
  vehicle: {port: 4001}
actions:
  - {name: /fibonacci, id: 9, type: test_msgs/action/Fibonacci, server: vehicle}
"""


@pytest.fixture(scope="module")
def action(tmp_path_factory):
    root = tmp_path_factory.mktemp("acts")
    (root / "pkg" / "msg").mkdir(parents=True)
    (root / "pkg" / "msg" / "Unused.msg").write_text("int8 x\n")
    (root / "uwgen.yaml").write_text(MANIFEST)
    package = generate(tmp_path_factory.mktemp("gen"), "uwgen_acts", folders=[root],
                       manifest=root / "uwgen.yaml")
    return package.ACTIONS[9]


def section_13() -> str:
    text = SPEC.read_text()
    return text[text.index("## 13. Actions"):]


def hexed(data: bytes) -> str:
    return data.hex(" ").upper()


def test_worked_bytes_of_section_13(action):
    vectors = {
        "goal": (action.encode_goal(7, Fibonacci.Goal(order=5)), "02 09 07 05"),
        "cancel": (action.encode_cancel(7), "02 09 07"),
        "accepted": (action.encode_answer(7, ACCEPTED), "03 09 07 01"),
        "rejected": (action.encode_answer(7, REJECTED), "03 09 07 00"),
        "canceling": (action.encode_answer(7, CANCELING), "03 09 07 03"),
        "refused": (action.encode_answer(7, CANCEL_REFUSED), "03 09 07 02"),
        "feedback": (action.encode_feedback(7, Fibonacci.Feedback(sequence=[0, 1, 1])),
                     "00 09 07 03 00 01 01"),
        "result": (action.encode_result(7, SUCCEEDED, Fibonacci.Result(sequence=[0, 1, 1, 2, 3, 5])),
                   "03 09 07 04 06 00 01 01 02 03 05"),
        "aborted": (action.encode_result(7, ABORTED, Fibonacci.Result()), "03 09 07 06 00"),
        "result received": (action.encode_result_status(7, received=True), "02 09 18 1F 00"),
        "result wanted": (action.encode_result_status(7, received=False), "02 09 18 1F 01"),
    }
    spec = section_13()
    for name, (data, wire) in vectors.items():
        assert hexed(data) == wire, name
        assert f"`{wire}`" in spec, f"{name} not in the spec"


def test_requests_decode_to_goal_or_cancel(action):
    handle, goal = action.decode_request(action.encode_goal(23, Fibonacci.Goal(order=40)))
    assert (handle, type(goal), goal.order) == (23, Fibonacci.Goal, 40)
    assert action.decode_request(bytes.fromhex("020900")) == (0, None)


def test_result_status_requests_are_told_from_goals_and_cancels(action):
    assert action.decode_result_status(bytes.fromhex("0209181f00")) == (7, True)
    assert action.decode_result_status(bytes.fromhex("0209182f01")) == (23, False)
    assert action.decode_result_status(action.encode_goal(7, Fibonacci.Goal(order=5))) is None
    assert action.decode_result_status(action.encode_cancel(0)) is None
    for bad in ("0209181f02", "0209181f", "0209183001", "0209181f0000"):   # code, cut, 48, extra
        with pytest.raises(DecodeError):
            action.decode_result_status(bytes.fromhex(bad))


def test_responses_decode_to_answers_or_results(action):
    assert action.decode_response(bytes.fromhex("03090703")) == (7, CANCELING, None)
    handle, status, result = action.decode_response(
        action.encode_result(3, SUCCEEDED, Fibonacci.Result(sequence=[1, 2])))
    assert (handle, status, list(result.sequence)) == (3, SUCCEEDED, [1, 2])
    assert type(result) is Fibonacci.Result


def test_feedback_round_trips_into_the_rclpy_class(action):
    handle, fb = action.decode_feedback(action.encode_feedback(1, Fibonacci.Feedback(sequence=[5])))
    assert (handle, type(fb), list(fb.sequence)) == (1, Fibonacci.Feedback, [5])


@pytest.mark.parametrize("payload, where", [
    ("03090709", "answer"),           # 9 is no answer code
    ("0309070700", "status"),         # 7 is no terminal status
    ("03090704", "answer"),           # a result without its fields
    ("0209181805", "handle"),         # handle 24: out of range
    ("020A0705", "id"),               # another action's id
    ("0009070300", "sequence"),       # feedback: 3 elements announced, 1 present
])
def test_malformed_payloads_raise_decode_error(action, payload, where):
    data = bytes.fromhex(payload)
    decode = {0: action.decode_feedback, 2: action.decode_request, 3: action.decode_response}[data[0]]
    with pytest.raises(DecodeError) as info:
        decode(data)
    assert info.value.path.startswith(where)


def test_encoders_refuse_bad_handles_and_codes(action):
    with pytest.raises(EncodeError, match="handle"):
        action.encode_cancel(24)
    with pytest.raises(EncodeError, match="answer"):
        action.encode_answer(1, SUCCEEDED)
    with pytest.raises(EncodeError, match="status"):
        action.encode_result(1, ACCEPTED, Fibonacci.Result())


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.one_of(st.binary(max_size=40),
                 st.lists(st.one_of(st.integers(-30, 300), st.text(max_size=3), st.binary(max_size=3),
                                    st.floats(allow_nan=False)), max_size=8)
                 .map(lambda items: bytes.fromhex("0309") + _pack(items)),
                 st.lists(st.integers(0, 30), max_size=6).map(lambda items: bytes.fromhex("0209") + _pack(items))))
def test_action_decoders_are_total(action, payload):
    # Any bytes: a value or DecodeError, nothing else (wire format 4, "a decoder is total").
    for decode in (action.decode_request, action.decode_response, action.decode_feedback):
        try:
            decode(payload)
        except DecodeError:
            pass


def _pack(items) -> bytes:
    from uwgen.runtime.wire.codec import pack_items
    return pack_items(list(items)) if items else b""


def test_an_action_has_a_schema_fingerprint_of_its_definition(action, tmp_path):
    # Same action, another result type on the same id: the fingerprint differs (section 10).
    assert len(action.fingerprint) == 4
    root = tmp_path / "src"
    (root / "fib_msgs" / "action").mkdir(parents=True)
    (root / "fib_msgs" / "action" / "Fibonacci.action").write_text(
        "int32 order\n---\nint64[] sequence\n---\nint32[] sequence\n")
    (root / "uwgen.yaml").write_text(MANIFEST.replace("test_msgs/action", "fib_msgs/action"))
    other = generate(tmp_path / "gen", "uwgen_acts_other", folders=[root],
                     manifest=root / "uwgen.yaml").ACTIONS[9]
    assert len(other.fingerprint) == 4 and other.fingerprint != action.fingerprint
