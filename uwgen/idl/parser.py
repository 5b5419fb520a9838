"""Parser for the ROS 2 `.msg`, `.srv` and `.action` languages into `uwgen.idl.model` objects.

Line by line, the rules are those of `rosidl_adapter.parser` (the reference ROS 2 uses
to turn `.msg` into IDL, from which rclpy's classes are generated), so uwgen and rclpy
agree on every field, bound, constant and default; `tests/idl/test_agreement.py` checks
this on every installed interface. The parser is stricter where rosidl_adapter would
crash, silently misread or accept something its own IDL step later rejects, and every
problem is a `DefinitionError` located as `file:line:column`.

Notes on the language (checked against rosidl_adapter, Jazzy):
- `#` starts a comment anywhere on a line, even inside a quoted string value.
- `char` is reported as `char` by rosidl_adapter (its IDL step maps it to uint8, which is
  what rclpy holds); uwgen keeps the base name `char`, an unsigned 8-bit integer.
- a bare `Header` means `<this package>/Header`: unlike ROS 1, ROS 2 does not special-case
  it, so a message must say `std_msgs/Header` (the library's error hints at that).
- nested types may be written `Type` (same package), `pkg/Type`, or `pkg/msg/Type` (the
  last is a uwgen extension; rosidl_adapter itself only takes the first two).
- a line containing `=` after the type declares a constant (`TYPE NAME=value`);
  otherwise it is a field `TYPE name [default]`.
- ROS 1's `time` and `duration` primitives are refused (ROS 2 cannot build them).
"""
from __future__ import annotations

import re
from pathlib import Path

from uwgen import safefile
from uwgen.idl import names
from uwgen.idl.model import (
    ACTION_PARTS,
    PRIMITIVE_TYPES,
    ActionDef,
    STRING_TYPES,
    ArrayKind,
    Constant,
    DefinitionError,
    Field,
    FieldType,
    MessageDef,
    ServiceDef,
    SourceRef,
)
from uwgen.idl.values import ValueProblem, parse_scalar, parse_value
from uwgen.runtime.wire.fragment import MAX_COUNT
from uwgen.runtime.wire.framing import MAX_PAYLOAD

SEPARATOR = "---"
# The largest size or bound a definition may give (docs/wire-format.md section 7, "The
# largest message"): no message longer than MAX_COUNT fragments of a frame's MAX_PAYLOAD
# bytes crosses the link; a string's character takes at least one byte of it, an array's
# element at least one bit (a bool of the packed profile). Anything larger could never be
# sent, and would only make the build write a module of that size.
MAX_MESSAGE_BYTES = MAX_COUNT * MAX_PAYLOAD        # 255 fragments of 255 bytes: 65 025
MAX_STRING_BOUND = MAX_MESSAGE_BYTES
MAX_ARRAY_SIZE = 8 * MAX_MESSAGE_BYTES            # 520 200
LIMIT_REASON = (f"no message over {MAX_MESSAGE_BYTES} bytes ({MAX_COUNT} fragments of {MAX_PAYLOAD}) "
                "crosses the link")
DEFINITION_LIMIT = 1024 ** 2   # the longest .msg/.srv/.action read (ROS's own are under 20 KiB)
_ROS1_TYPES = {"time": "builtin_interfaces/Time", "duration": "builtin_interfaces/Duration"}


class _Line:
    """One significant line: its text without comment or trailing blanks, and where it is."""

    __slots__ = ("text", "number", "path")

    def __init__(self, text: str, number: int, path: Path):
        self.text = text
        self.number = number
        self.path = path

    def at(self, column0: int) -> SourceRef:
        return SourceRef(self.path, self.number, column0 + 1)

    def error(self, column0: int, message: str) -> DefinitionError:
        return DefinitionError(self.at(column0), message)


def parse_type(text: str, package: str, where: _Line, column0: int = 0) -> FieldType:
    """Parse a type spelling such as `int32`, `string<=8[<=4]`, `geometry_msgs/Point[]`.

    Nested message names come back fully qualified (`pkg/msg/Name`); whether they exist
    is the library's business, not the parser's.
    """
    array = ArrayKind.NONE
    size: int | None = None
    base_text = text
    if text.endswith("]"):
        open_at = text.rfind("[")
        if open_at == -1:
            raise where.error(column0 + len(text) - 1, f"malformed array type '{text}': ']' without '['")
        inner = text[open_at + 1:-1]
        base_text = text[:open_at]
        if inner == "":
            array = ArrayKind.UNBOUNDED
        else:
            bounded = inner.startswith("<=")
            digits = inner[2:] if bounded else inner
            digits_at = column0 + open_at + 1 + (2 if bounded else 0)
            size = _positive_int(digits, "array bound" if bounded else "array size", text, where, digits_at)
            array = ArrayKind.BOUNDED if bounded else ArrayKind.FIXED
        if "[" in base_text or "]" in base_text:
            raise where.error(column0 + text.find("["), f"malformed array type '{text}': arrays of arrays are not supported")
    elif "[" in text or "]" in text:
        at = min(i for i in (text.find("["), text.find("]")) if i >= 0)
        raise where.error(column0 + at, f"malformed array type '{text}': expected T[N], T[<=N] or T[]")
    if base_text == "":
        raise where.error(column0, f"missing element type in '{text}'")

    if base_text in PRIMITIVE_TYPES:
        return FieldType(base_text, array, size)
    if base_text in _ROS1_TYPES:
        raise where.error(column0, f"'{base_text}' is a ROS 1 type; in ROS 2 use {_ROS1_TYPES[base_text]}")
    if "<=" in base_text:
        head, _, bound_text = base_text.partition("<=")
        if head not in STRING_TYPES:
            raise where.error(column0, f"only string and wstring can have a '<=' bound, not '{head}'")
        bound = _positive_int(bound_text, "string bound", text, where, column0 + len(head) + 2)
        return FieldType(head, array, size, bound)
    return FieldType(_message_type(base_text, package, where, column0), array, size)


def _shown(text: str, keep: int = 40) -> str:
    """A spelling as the file has it, cut short when long (a size of 5 000 digits)."""
    return text if len(text) <= keep else f"{text[:keep]}... ({len(text)} characters)"


def _positive_int(digits: str, what: str, text: str, where: _Line, column0: int) -> int:
    limit = MAX_STRING_BOUND if what == "string bound" else MAX_ARRAY_SIZE
    if not digits.isascii() or not digits.isdigit():
        raise where.error(column0, f"{what} in '{_shown(text)}' must be a positive integer, got '{_shown(digits)}'")
    if len(digits.lstrip("0")) > len(str(limit)) or int(digits) > limit:
        raise where.error(column0, f"{what} in '{_shown(text)}' is {_shown(digits)}, more than uwgen's "
                                   f"limit of {limit}: {LIMIT_REASON}")
    value = int(digits)
    if value <= 0:
        raise where.error(column0, f"{what} in '{_shown(text)}' must be > 0, got {value}")
    return value


def _message_type(text: str, package: str, where: _Line, column0: int) -> str:
    parts = text.split("/")
    if len(parts) == 1:
        pkg, ns, name = package, "msg", parts[0]
    elif len(parts) == 2:
        pkg, ns, name = parts[0], "msg", parts[1]
    elif len(parts) == 3:
        pkg, ns, name = parts
        if ns != "msg":
            raise where.error(column0 + len(pkg) + 1, f"field type '{text}': only message types ('pkg/msg/Name') can be fields, not '{ns}'")
    else:
        raise where.error(column0, f"unknown type '{text}': expected a primitive, 'Type', 'pkg/Type' or 'pkg/msg/Type'")
    if not names.is_package_name(pkg):
        if len(parts) == 1:
            raise where.error(column0, f"unknown type '{text}'")
        raise where.error(column0, f"'{pkg}' in type '{text}' is not a valid package name (lower case letters, digits, '_')")
    if not names.is_message_name(name):
        name_at = column0 + len(text) - len(name)
        if len(parts) == 1:
            raise where.error(column0, f"unknown type '{text}' (not a primitive, and message names are CamelCase)")
        raise where.error(name_at, f"'{name}' in type '{text}' is not a valid message name (CamelCase letters and digits)")
    return f"{pkg}/{ns}/{name}"


def _significant_lines(lines: list[str], first_number: int, path: Path) -> list[_Line]:
    """The lines that declare something, comments and blanks removed (as rosidl_adapter)."""
    out = []
    for offset, raw in enumerate(lines):
        text = raw.replace("\t", " ")
        hash_at = text.find("#")
        if hash_at >= 0:
            text = text[:hash_at]
        text = text.rstrip()
        if text.strip():
            out.append(_Line(text, first_number + offset, path))
    return out


def parse_message_lines(
    lines: list[str],
    package: str,
    name: str,
    path: Path,
    namespace: str = "msg",
    first_line: int = 1,
) -> MessageDef:
    """Parse the lines of one message body; line numbers start at `first_line`."""
    fields: list[Field] = []
    constants: list[Constant] = []
    field_lines: dict[str, int] = {}
    constant_lines: dict[str, int] = {}
    for line in _significant_lines(lines, first_line, path):
        text = line.text
        if text.strip() == SEPARATOR:
            if namespace == "msg":
                raise line.error(0, "'---' separates a service's request and response; it is not allowed in a .msg file")
            what = "an action" if namespace == "action" else "a service"
            raise line.error(0, f"{what} separator must be exactly '---', alone on its line without spaces")
        if text[0] == " ":
            raise line.error(0, "unexpected indentation: a field or constant must start at column 1")
        type_text, _, rest = text.partition(" ")
        rest_at = len(type_text) + 1 + (len(rest) - len(rest.lstrip()))
        rest = rest.lstrip()
        if not rest:
            raise line.error(len(type_text), f"expected 'TYPE NAME' but the line has only '{type_text}'")
        if "=" in rest:
            constants.append(_constant(line, type_text, rest, rest_at, constant_lines))
        else:
            fields.append(_field(line, type_text, rest, rest_at, package, field_lines))
    return MessageDef(package, name, fields, constants, source=path, namespace=namespace)


def _field(line: _Line, type_text: str, rest: str, rest_at: int, package: str, seen: dict[str, int]) -> Field:
    ftype = parse_type(type_text, package, line)
    field_name, _, default_text = rest.partition(" ")
    default_at = rest_at + len(field_name) + 1 + (len(default_text) - len(default_text.lstrip()))
    default_text = default_text.lstrip()
    if not names.is_field_name(field_name):
        raise line.error(
            rest_at,
            f"'{field_name}' is not a valid field name (lower case letters, digits and '_', "
            "starting with a letter, no '__', not ending with '_')",
        )
    if field_name in seen:
        raise line.error(rest_at, f"duplicate field '{field_name}' (first defined at line {seen[field_name]})")
    seen[field_name] = line.number
    default = None
    if default_text:
        try:
            default = parse_value(ftype, default_text)
        except ValueProblem as exc:
            raise line.error(default_at + exc.offset, f"bad default for field '{field_name}': {exc.message}") from None
    return Field(field_name, ftype, default, line.at(0))


def _constant(line: _Line, type_text: str, rest: str, rest_at: int, seen: dict[str, int]) -> Constant:
    name_part, _, value_text = rest.partition("=")
    const_name = name_part.rstrip()
    value_at = rest_at + len(name_part) + 1 + (len(value_text) - len(value_text.lstrip()))
    value_text = value_text.lstrip()
    if type_text not in PRIMITIVE_TYPES or type_text in _ROS1_TYPES:
        raise line.error(
            0,
            f"constant '{const_name}' has type '{type_text}': constants must be a primitive type "
            "(bool, integers, floats, string, wstring), not arrays, bounded strings or messages",
        )
    if not names.is_constant_name(const_name):
        raise line.error(
            rest_at,
            f"'{const_name}' is not a valid constant name (UPPER_CASE letters, digits and '_'); "
            "a line with '=' declares a constant TYPE NAME=value",
        )
    if const_name in seen:
        raise line.error(rest_at, f"duplicate constant '{const_name}' (first defined at line {seen[const_name]})")
    seen[const_name] = line.number
    try:
        value = parse_scalar(type_text, value_text)
    except ValueProblem as exc:
        raise line.error(value_at + exc.offset, f"bad value for constant '{const_name}': {exc.message}") from None
    return Constant(const_name, type_text, value, line.at(0))


def parse_message_string(text: str, package: str, name: str, path: Path | str = "<string>") -> MessageDef:
    """Parse the text of a `.msg` file defining `package/msg/name`."""
    path = Path(path)
    _check_names(package, name, path)
    return parse_message_lines(text.splitlines(), package, name, path, "msg")


def parse_service_string(text: str, package: str, name: str, path: Path | str = "<string>") -> ServiceDef:
    """Parse the text of a `.srv` file: request `Name_Request`, `---`, response `Name_Response`."""
    path = Path(path)
    _check_names(package, name, path)
    lines = text.splitlines()
    separators = [i for i, line in enumerate(lines) if line == SEPARATOR]
    if not separators:
        _check_separator_lines(lines, path, "a service")
        raise DefinitionError(SourceRef(path, 1, 1), "missing '---' between the request and the response of a service")
    if len(separators) > 1:
        raise DefinitionError(
            SourceRef(path, separators[1] + 1, 1),
            f"extra '---': a service has exactly one separator (the first is at line {separators[0] + 1})",
        )
    cut = separators[0]
    request = parse_message_lines(lines[:cut], package, f"{name}_Request", path, "srv", 1)
    response = parse_message_lines(lines[cut + 1:], package, f"{name}_Response", path, "srv", cut + 2)
    return ServiceDef(package, name, request, response, source=path)


def parse_action_string(text: str, package: str, name: str, path: Path | str = "<string>") -> ActionDef:
    """Parse the text of a `.action` file: goal `Name_Goal`, `---`, result `Name_Result`,
    `---`, feedback `Name_Feedback` (as rosidl_adapter.parser.parse_action_string)."""
    path = Path(path)
    _check_names(package, name, path)
    lines = text.splitlines()
    separators = [i for i, line in enumerate(lines) if line == SEPARATOR]
    if len(separators) != 2:
        _check_separator_lines(lines, path, "an action")
        if len(separators) > 2:
            raise DefinitionError(
                SourceRef(path, separators[2] + 1, 1),
                "extra '---': an action has exactly two separators (goal --- result --- feedback)",
            )
        at = SourceRef(path, (separators[0] + 1) if separators else 1, 1)
        raise DefinitionError(at, f"an action needs two '---' lines (goal --- result --- feedback), "
                                  f"found {len(separators)}")
    bounds = [(0, separators[0]), (separators[0] + 1, separators[1]), (separators[1] + 1, len(lines))]
    goal, result, feedback = (
        parse_message_lines(lines[a:b], package, f"{name}_{part}", path, "action", a + 1)
        for part, (a, b) in zip(ACTION_PARTS, bounds))
    return ActionDef(package, name, goal, result, feedback, source=path)


# A line that was meant as a separator: dashes (or dash-like characters) and spaces only,
# maybe a comment after them.
_SEPARATOR_LIKE = re.compile(r"\s*[-\u2012\u2013\u2014\u2015][-\u2012\u2013\u2014\u2015\s]*(#.*)?")


def _check_separator_lines(lines: list[str], path: Path, what: str) -> None:
    """A separator written wrongly (`----`, ` ---`, `--- `, an em dash) is an error at its own
    line and column, not a missing separator at the start of the file."""
    for i, line in enumerate(lines):
        if line != SEPARATOR and _SEPARATOR_LIKE.fullmatch(line):
            column = len(line) - len(line.lstrip()) + 1
            raise DefinitionError(
                SourceRef(path, i + 1, column),
                f"{what} separator must be exactly '---', alone on its line without spaces: "
                f"got {line.strip()!r}")


def _check_names(package: str, name: str, path: Path) -> None:
    if not names.is_package_name(package):
        raise DefinitionError(SourceRef(path, 1, 1), f"'{package}' is not a valid package name (lower case letters, digits, '_')")
    if not names.is_message_name(name):
        raise DefinitionError(SourceRef(path, 1, 1), f"'{name}' is not a valid interface name (CamelCase letters and digits)")


def read_text(path: Path) -> str:
    """The file's text as UTF-8, read with uwgen.safefile (a regular file of at most
    DEFINITION_LIMIT bytes); a problem is a located DefinitionError."""
    try:
        return safefile.read_text(path, "interface definition", DEFINITION_LIMIT)
    except safefile.UnreadableFile as exc:
        raise DefinitionError(SourceRef(path, exc.line or 1, exc.column or 1), exc.reason) from None


def parse_file(path: Path | str, package: str | None = None):
    """Parse `<package>/msg/Name.msg`, `<package>/srv/Name.srv` or `<package>/action/Name.action`.

    The package defaults to the name of the folder above `msg/`, `srv/` or `action/`.
    Returns a MessageDef, a ServiceDef or an ActionDef.
    """
    path = Path(path)
    if package is None:
        package = path.parent.parent.name
    text = read_text(path)
    if path.suffix == ".msg":
        return parse_message_string(text, package, path.stem, path)
    if path.suffix == ".srv":
        return parse_service_string(text, package, path.stem, path)
    if path.suffix == ".action":
        return parse_action_string(text, package, path.stem, path)
    raise DefinitionError(SourceRef(path, 1, 1),
                          f"unsupported interface file '{path.name}': expected .msg, .srv or .action")
