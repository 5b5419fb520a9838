"""The key file door: any content gives the key or a SecurityError naming the file; never
another exception. (There are no security state files behind this door: each start
takes a fresh epoch instead, docs/security.md.)"""
from __future__ import annotations

import os

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.security.keys import MASTER_KEY_BYTES, SecurityError, read_key_file

FUZZ = settings(max_examples=200, deadline=10_000,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
HEX = "0123456789abcdefABCDEF"


def test_a_key_file_of_one_line_of_hex_digits_is_read(tmp_path):
    path = tmp_path / "net.key"
    path.write_text("# a comment\n" + "ab" * MASTER_KEY_BYTES + "\n")
    os.chmod(path, 0o600)
    assert read_key_file(path) == bytes([0xAB]) * MASTER_KEY_BYTES


@FUZZ
@given(st.one_of(st.binary(max_size=200),
                 st.text(alphabet=HEX + "#\n \t\r\x00é", max_size=120),
                 st.text(alphabet=HEX, min_size=2 * MASTER_KEY_BYTES - 2, max_size=2 * MASTER_KEY_BYTES + 2),
                 st.just("f" * 100_000)))
def test_any_key_file_content_gives_the_key_or_an_error_naming_the_file(tmp_path, data):
    path = tmp_path / "net.key"
    path.write_bytes(data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data)
    os.chmod(path, 0o600)
    try:
        key = read_key_file(path)
    except SecurityError as error:
        assert str(path) in str(error) and len(str(error)) < 1000
    else:
        assert len(key) == MASTER_KEY_BYTES
