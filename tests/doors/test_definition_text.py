"""The .msg/.srv/.action door: any text gives a definition or a DefinitionError at its
file:line:column, in well under a second; never another exception, never a hang."""
from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.idl.model import DefinitionError
from uwgen.idl.parser import parse_action_string, parse_message_string, parse_service_string

from .helpers import bounded

# A deadline per example: a pattern that backtracks shows up as an example over a second.
FUZZ = settings(max_examples=300, deadline=10_000, suppress_health_check=[HealthCheck.too_slow])

LONG_NAMES = ["POWER_SUPPLY_TECHNOLOGY_UNKNOWN" + "x" * 2, "A" * 200 + "_" * 3 + "b", "_" * 100,
              "a" * 300 + "__", "Pkg" * 80 + "/Foo"]
NUMBERS = ["9" * 400, "-" + "9" * 400, "1e400", "-1e400", "0x" + "f" * 200, "nan", "inf", "1" * 30]
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


@FUZZ
@given(TEXT)
def test_any_message_text_gives_a_definition_or_a_located_error(text):
    try:
        parse_message_string(text, "pkg", "Msg", "Msg.msg")
    except DefinitionError as error:
        _located(error, text)


@FUZZ
@given(TEXT)
def test_any_service_text_gives_a_definition_or_a_located_error(text):
    try:
        parse_service_string(text, "pkg", "Srv", "Srv.srv")
    except DefinitionError as error:
        _located(error, text)


@FUZZ
@given(st.lists(TEXT, min_size=1, max_size=3).map("---\n".join))
def test_any_action_text_gives_a_definition_or_a_located_error(text):
    try:
        parse_action_string(text, "pkg", "Act", "Act.action")
    except DefinitionError as error:
        _located(error, text)
