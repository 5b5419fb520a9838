"""The key file and security state file doors: any content gives a key (a state) or a
SecurityError naming the file; never another exception (RecursionError from JSON nested
deep, OverflowError from 1e400, a 400-digit sequence number accepted)."""
from __future__ import annotations

import json
import os

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.security.keys import MASTER_KEY_BYTES, SecurityError, read_key_file
from uwgen.security.state import State, StateFile
from uwgen.security.wire import MAX_SENDER, MAX_SEQ

FUZZ = settings(max_examples=200, deadline=1000,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
GOOD = {"version": 1, "key_id": "k1", "reserved": 512, "floors": {"2": 48}}


def load_state(tmp_path, data: bytes | str) -> State:
    path = tmp_path / "net.key.n.a.k1.state"
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return StateFile(path, "k1").load()


def damaged(tmp_path, data) -> str:
    with pytest.raises(SecurityError) as info:
        load_state(tmp_path, data)
    assert "net.key.n.a.k1.state" in str(info.value)
    return str(info.value)


def with_(**changes) -> str:
    return json.dumps({**GOOD, **changes})


def test_a_good_state_file_loads(tmp_path):
    assert load_state(tmp_path, json.dumps(GOOD)) == State("k1", 512, {2: 48})
    assert load_state(tmp_path, with_(reserved=MAX_SEQ + 1)).reserved == MAX_SEQ + 1


@pytest.mark.parametrize("data, says", [
    ("[" * 100_000 + "]" * 100_000, "damaged"),                          # RecursionError before
    ('{"version": 1, "key_id": "k1", "reserved": 1e400, "floors": {}}', "reserved inf"),  # OverflowError
    (with_(reserved=10 ** 400), "reserved 1000"),                        # accepted before
    (with_(reserved=MAX_SEQ + 2), f"0..{MAX_SEQ + 1}"),
    (with_(reserved=2.5), "reserved 2.5"),
    (with_(reserved=True), "reserved True"),
    (with_(floors={str(MAX_SENDER + 1): 3}), "sender id"),
    (with_(floors={"1": 10 ** 30}), "floor"),
    (with_(floors={"-1": 3}), "sender id"),
])
def test_a_state_file_out_of_range_is_refused_naming_the_file(tmp_path, data, says):
    message = damaged(tmp_path, data)
    assert "is damaged" in message and says in message and len(message) < 400


JSON_PIECES = st.recursive(
    st.none() | st.booleans() | st.integers(-2 ** 70, 2 ** 70) | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12)


@FUZZ
@given(st.one_of(
    st.binary(max_size=200),
    st.dictionaries(st.sampled_from(["version", "key_id", "reserved", "floors", "x"]), JSON_PIECES,
                    max_size=5).map(json.dumps),
    st.fixed_dictionaries({"version": st.just(1), "key_id": st.just("k1"), "reserved": JSON_PIECES,
                           "floors": JSON_PIECES}).map(json.dumps)))
def test_any_state_file_content_loads_or_is_refused_naming_the_file(tmp_path, data):
    try:
        state = load_state(tmp_path, data)
    except SecurityError as error:
        assert "net.key.n.a.k1.state" in str(error)
    else:
        assert 0 <= state.reserved <= MAX_SEQ + 1
        assert all(0 <= s <= MAX_SENDER and 0 <= f <= MAX_SEQ + 1 for s, f in state.floors.items())


@FUZZ
@given(st.one_of(st.binary(max_size=200),
                 st.text(alphabet="0123456789abcdefABCDEF#\n \t\r\x00é", max_size=120)))
def test_any_key_file_content_gives_the_key_or_an_error_naming_the_file(tmp_path, data):
    path = tmp_path / "net.key"
    path.write_bytes(data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data)
    os.chmod(path, 0o600)
    try:
        key = read_key_file(path)
    except SecurityError as error:
        assert str(path) in str(error)
    else:
        assert len(key) == MASTER_KEY_BYTES
