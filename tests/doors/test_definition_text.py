"""The .msg/.srv/.action door: any text gives a definition or a DefinitionError at its
file:line:column, in well under a second; never another exception, never a hang. What parses
also builds and analyses (sizes and bounds of thousands of digits, above 2^63, or a module of
400 MB are refused where they are written, against a documented maximum)."""
from __future__ import annotations

import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.idl.model import DefinitionError
from uwgen.idl.parser import (MAX_ARRAY_SIZE, MAX_MESSAGE_BYTES, MAX_STRING_BOUND, parse_action_string,
                              parse_message_string, parse_service_string)
from uwgen.runtime.wire.fragment import MAX_COUNT
from uwgen.runtime.wire.framing import MAX_PAYLOAD

from .helpers import bounded, definition_through_build, examples

# A deadline per example: a pattern that backtracks shows up as an example over a second.
FUZZ = settings(max_examples=examples(300), deadline=10_000,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

LONG_NAMES = ["POWER_SUPPLY_TECHNOLOGY_UNKNOWN" + "x" * 2, "A" * 200 + "_" * 3 + "b", "_" * 100,
              "a" * 300 + "__", "Pkg" * 80 + "/Foo"]
NUMBERS = ["9" * 400, "9" * 5000, str(2 ** 63 + 1), str(2 ** 64), str(MAX_ARRAY_SIZE + 1), "100000000",
           "-" + "9" * 400, "1e400", "-1e400", "0x" + "f" * 200, "nan", "inf", "1" * 30]
TOKENS = ["int32 ", "uint8 ", "float64 ", "string ", "string<=", "[<=", "[]", "[", "]", "---\n",
          "=", " = ", " x", " X=", "\n", "'", '"', "#", "pkg/Foo ", "0x", "-", "nan", *LONG_NAMES, *NUMBERS]
ALPHABET = "abcXYZ019_/ <=[]#=-'\"\\,.\t\n"
TEXT = st.lists(st.one_of(st.text(alphabet=ALPHABET, max_size=6), st.sampled_from(TOKENS)),
                max_size=25).map("".join)


def _located(error: DefinitionError, text: str) -> None:
    assert str(error.where.path).endswith(("Msg.msg", "Srv.srv", "Act.action"))
    assert 1 <= error.where.line <= text.count("\n") + 2 and error.where.column >= 1


def test_a_long_constant_name_that_fails_late_is_refused_at_once():
    # rosidl's pattern for constant names backtracked exponentially on this line (34 s with
    # two trailing letters, five times longer for each two more): the name is now checked in
    # linear time, so even a 60-letter tail is refused at once.
    code = ("from uwgen.idl.parser import parse_message_string\n"
            "from uwgen.idl.model import DefinitionError\n"
            "for tail in ('xx', 'x' * 60):\n"
            "    try:\n"
            "        parse_message_string(f'uint8 POWER_SUPPLY_TECHNOLOGY_UNKNOWN{tail} = 0', 'pkg', 'Msg', 'Msg.msg')\n"
            "    except DefinitionError as e:\n"
            "        print(e)\n")
    res = bounded(code, seconds=20)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert len(lines) == 2 and all(l.startswith("Msg.msg:1:7: 'POWER_SUPPLY_TECHNOLOGY_UNKNOWNx") for l in lines)
    assert all("is not a valid constant name" in l for l in lines)


def test_constant_names_keep_rosidls_rules():
    from uwgen.idl.names import is_constant_name
    for good in ("A", "A1", "A_B", "POWER_SUPPLY_TECHNOLOGY_UNKNOWN", "X9_Y8_Z7", "A_1"):
        assert is_constant_name(good), good
    for bad in ("", "a", "1A", "_A", "A_", "A__B", "Ab", "A-B", "A B", "A_b"):
        assert not is_constant_name(bad), bad


def _parsed_then_built(parse, text: str, path: str, tmp_path, kind: str) -> None:
    """`text` parses or fails at its file:line:column; what parses builds and analyses too."""
    try:
        parse(text, "pkg", path.split(".")[0], path)
    except DefinitionError as error:
        _located(error, text)
        return
    folder = tmp_path / f"build{len(list(tmp_path.iterdir()))}"
    said = definition_through_build(folder, text, kind)
    assert said == "built" or f"Fuzz.{kind}:" in said or "fuzz" in said, said


@FUZZ
@given(TEXT)
def test_any_message_text_gives_a_definition_or_a_located_error(tmp_path, text):
    _parsed_then_built(parse_message_string, text, "Msg.msg", tmp_path, "msg")


@FUZZ
@given(TEXT)
def test_any_service_text_gives_a_definition_or_a_located_error(tmp_path, text):
    _parsed_then_built(parse_service_string, text, "Srv.srv", tmp_path, "srv")


@FUZZ
@given(st.lists(TEXT, min_size=1, max_size=3).map("---\n".join))
def test_any_action_text_gives_a_definition_or_a_located_error(tmp_path, text):
    _parsed_then_built(parse_action_string, text, "Act.action", tmp_path, "action")


# -- sizes and bounds ------------------------------------------------------------------------

def test_the_size_limits_are_the_largest_message_the_fragments_carry():
    assert MAX_MESSAGE_BYTES == MAX_COUNT * MAX_PAYLOAD
    assert MAX_STRING_BOUND == MAX_MESSAGE_BYTES          # a character takes a byte at least
    assert MAX_ARRAY_SIZE == 8 * MAX_MESSAGE_BYTES        # an element a bit at least (packed bool)


@pytest.mark.parametrize("line, column, what", [
    ("uint8[100000000] a", 7, "array size"),
    ("uint8[" + "9" * 5000 + "] a", 7, "array size"),
    ("float64[" + "9" * 400 + "] a", 9, "array size"),
    (f"int64[{2 ** 63 + 1}] a", 7, "array size"),
    (f"bool[<={'7' * 4400}] a", 8, "array bound"),
    (f"string<={'3' * 4400} a", 9, "string bound"),
    (f"string<={MAX_STRING_BOUND + 1}[2] a", 9, "string bound"),
    (f"uint8[{MAX_ARRAY_SIZE + 1}] a", 7, "array size"),
])
def test_a_size_or_bound_over_the_limit_is_a_short_located_error(line, column, what):
    with pytest.raises(DefinitionError) as info:
        parse_message_string(f"int32 x\n{line}\n", "pkg", "Msg", "Msg.msg")
    message = str(info.value)
    assert message.startswith(f"Msg.msg:2:{column}: {what} in ") and len(message) < 400, message
    assert "more than uwgen's limit of" in message and "crosses the link" in message


def test_the_largest_sizes_and_bounds_parse(tmp_path):
    text = (f"uint8[{MAX_ARRAY_SIZE}] a\nbool[<={MAX_ARRAY_SIZE}] b\nstring<={MAX_STRING_BOUND} s\n"
            f"string<={MAX_STRING_BOUND}[<={MAX_ARRAY_SIZE}] t\n")
    msg = parse_message_string(text, "pkg", "Msg", "Msg.msg")
    assert [f.type.size for f in msg.fields] == [MAX_ARRAY_SIZE, MAX_ARRAY_SIZE, None, MAX_ARRAY_SIZE]
    assert definition_through_build(tmp_path, text, "msg", "packed") == "built"


# Sizes as the file spells them (a 5 000-digit number cannot even be drawn as an int and
# printed: Python refuses int-to-text conversions past 4 300 digits).
HUGE = st.one_of(st.integers(0, 2 * MAX_ARRAY_SIZE).map(str), st.integers(0, 2 ** 70).map(str),
                 st.sampled_from([str(n) for n in (MAX_ARRAY_SIZE, MAX_ARRAY_SIZE + 1, MAX_STRING_BOUND,
                                                   MAX_STRING_BOUND + 1, 2 ** 63, 2 ** 63 + 1, 2 ** 64)]
                                 + ["1" + "0" * 399, "1" + "0" * 4300, "9" * 5000, "0" * 30 + "7"]))
PRIMITIVE = st.sampled_from(["bool", "uint8", "int16", "float32", "float64", "int64", "char", "byte"])


@st.composite
def sized_line(draw) -> str:
    n = draw(HUGE)
    shape = draw(st.sampled_from(["[{n}]", "[<={n}]", "[]"]))
    element = draw(st.one_of(PRIMITIVE, st.just("string"),
                             st.builds("string<={}".format, HUGE), st.builds("wstring<={}".format, HUGE)))
    return f"{element}{shape.format(n=n)} f{draw(st.integers(0, 9))}"


@settings(max_examples=examples(40), deadline=20_000,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(lines=st.lists(sized_line(), min_size=1, max_size=3, unique_by=lambda l: l.split()[-1]),
       kind=st.sampled_from(["msg", "srv", "action"]), profile=st.sampled_from(["native", "packed"]))
def test_any_size_or_bound_builds_or_is_refused_where_it_is_written(tmp_path, lines, kind, profile):
    body = "\n".join(lines) + "\n"
    text = {"msg": body, "srv": body + "---\n" + body, "action": body + "---\nint8 r\n---\n" + body}[kind]
    folder = tmp_path / f"build{len(list(tmp_path.iterdir()))}"
    said = definition_through_build(folder, text, kind, profile if kind == "msg" else "native")
    assert said == "built" or (f"Fuzz.{kind}:" in said and len(said) < 2000), said
    sizes = re.findall(r"\[(?:<=)?(\d+)\]", text)
    assert said != "built" or all(len(n.lstrip("0")) < 10 and int(n) <= MAX_ARRAY_SIZE for n in sizes), said
