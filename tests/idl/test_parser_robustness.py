"""Any definition text gives a definition or a located DefinitionError, never another exception."""
from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from uwgen.idl.model import DefinitionError
from uwgen.idl.parser import parse_message_string, parse_service_string

ALPHABET = "abcXYZ019_/ <=[]#=-'\"\\,.\t\n"
TOKENS = ["int32 ", "string<=", "[<=", "[]", "---\n", "=", " x", " X=", "\n", "'", '"', "#", "pkg/Foo ", "0x", "-", "nan"]
TEXT = st.lists(st.one_of(st.text(alphabet=ALPHABET, max_size=6), st.sampled_from(TOKENS)), max_size=25).map("".join)


@settings(max_examples=500, deadline=None)
@given(TEXT)
def test_random_message_text_never_raises_anything_else(text):
    try:
        parse_message_string(text, "pkg", "Msg", "Msg.msg")
    except DefinitionError as error:
        assert error.where.line >= 1 and error.where.column >= 1


@settings(max_examples=500, deadline=None)
@given(TEXT)
def test_random_service_text_never_raises_anything_else(text):
    try:
        parse_service_string(text, "pkg", "Srv", "Srv.srv")
    except DefinitionError as error:
        assert error.where.line >= 1 and error.where.column >= 1
