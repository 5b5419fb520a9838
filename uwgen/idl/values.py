"""Literal values of the `.msg` language: constants and field defaults.

The rules follow `rosidl_adapter.parser` (the reference ROS 2 uses to turn `.msg` into
IDL), because the defaults of rclpy's classes come from it: a value uwgen reads must be
the value rclpy holds. Where rosidl_adapter is laxer than the type allows, uwgen is
stricter and says so:

- a float32 value that does not fit a float32 (e.g. 1e39) is refused; so is a float64
  literal that overflows to infinity without being spelled `inf`;
- string arrays must separate their elements with commas (rosidl_adapter also takes
  `["a" "b"]`) and may not end with a comma.

Problems raise `ValueProblem` with an offset into the literal, so the parser can point
at the exact column.
"""
from __future__ import annotations

import math
import re
import struct

from uwgen.idl.model import FLOAT_TYPES, INTEGER_RANGES, STRING_TYPES, ArrayKind, FieldType

_TRUE = ("true", "1")
_FALSE = ("false", "0")


class ValueProblem(Exception):
    """A literal that does not fit its type; `offset` is where in the literal (0-based)."""

    def __init__(self, message: str, offset: int = 0):
        super().__init__(message)
        self.message = message
        self.offset = offset


def parse_scalar(base: str, text: str, string_bound: int | None = None):
    """The value of one literal of primitive type `base` (not an array)."""
    if base == "bool":
        low = text.lower()
        if low in _TRUE:
            return True
        if low in _FALSE:
            return False
        raise ValueProblem(f"'{text}' is not a bool: use true, false, 1 or 0")
    if base in INTEGER_RANGES:
        return _parse_integer(base, text)
    if base in FLOAT_TYPES:
        return _parse_float(base, text)
    if base in STRING_TYPES:
        return _parse_string(base, text, string_bound)
    raise ValueProblem(f"type '{base}' cannot have a literal value")


def _parse_integer(base: str, text: str) -> int:
    lo, hi = INTEGER_RANGES[base]
    # As rosidl_adapter: decimal first, then Python prefixes (0x, 0o, 0b).
    try:
        value = int(text)
    except ValueError:
        try:
            value = int(text, 0)
        except ValueError:
            raise ValueProblem(f"'{text}' is not an integer (type {base})") from None
    if not lo <= value <= hi:
        raise ValueProblem(f"{value} is out of range for {base} ({lo}..{hi})")
    return value


def _parse_float(base: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueProblem(
            f"'{text}' is not a floating point number (type {base}; use '.' as the separator)"
        ) from None
    if math.isinf(value) and "inf" not in text.lower():
        raise ValueProblem(f"{text} is out of range for {base}")
    if base == "float32" and math.isfinite(value):
        try:
            struct.pack("<f", value)
        except OverflowError:
            raise ValueProblem(f"{text} is out of range for float32 (about ±3.4028235e38)") from None
    return value


def _parse_string(base: str, text: str, bound: int | None) -> str:
    # Outer quotes (either kind) are removed so leading/trailing spaces can be kept;
    # inside, that quote must be escaped as \" or \'; other backslashes stay as written.
    value = text
    for quote in ('"', "'"):
        if len(text) >= 1 and text.startswith(quote) and text.endswith(quote):
            inner = text[1:-1]
            bad = re.search(r"(?<!\\)" + quote, inner)
            if bad is not None:
                raise ValueProblem(
                    f"unescaped {quote} inside a {quote}-quoted string (write \\{quote})",
                    bad.start() + 1,
                )
            value = inner.replace("\\" + quote, quote)
            break
    if bound is not None and len(value) > bound:
        raise ValueProblem(f"string of {len(value)} characters exceeds the bound {base}<={bound}")
    return value


def parse_value(ftype: FieldType, text: str):
    """A default value for a field of type `ftype`: a scalar, or a tuple for arrays."""
    if not ftype.is_primitive:
        raise ValueProblem(
            f"a field of message type {ftype.base} cannot have a default value "
            "(defaults are only allowed for primitive types)"
        )
    if not ftype.is_array:
        return parse_scalar(ftype.base, text, ftype.string_bound)
    if not (text.startswith("[") and text.endswith("]")) or len(text) < 2:
        raise ValueProblem(f"an array default must be written [a, b, ...], got '{text}'")
    inner = text[1:-1]
    if ftype.base in STRING_TYPES:
        items = _split_string_items(inner)
    else:
        items = []
        if inner:
            pos = 1
            for piece in inner.split(","):
                items.append((piece, pos))
                pos += len(piece) + 1
    count = len(items)
    if ftype.array is ArrayKind.FIXED and count != ftype.size:
        raise ValueProblem(f"{ftype} needs exactly {ftype.size} elements, got {count}")
    if ftype.array is ArrayKind.BOUNDED and count > ftype.size:
        raise ValueProblem(f"{ftype} allows at most {ftype.size} elements, got {count}")
    values = []
    for index, (piece, pos) in enumerate(items):
        stripped = piece.strip()
        offset = pos + (len(piece) - len(piece.lstrip()))
        if not stripped and ftype.base not in STRING_TYPES:
            raise ValueProblem(f"element {index} is empty", offset)
        try:
            values.append(parse_scalar(ftype.base, stripped, ftype.string_bound))
        except ValueProblem as exc:
            raise ValueProblem(f"element {index}: {exc.message}", offset + exc.offset) from None
    return tuple(values)


def _split_string_items(inner: str) -> list[tuple[str, int]]:
    """Split the inside of a string-array literal into (element text, offset) pairs.

    Elements are quoted ("..." or '...', with \\" or \\' for the quote itself) or bare
    (up to the next comma). A quoted element yields its content, which then goes through
    the scalar string rules again (what rosidl_adapter does, so `["'a'"]` is `a`).
    Offsets are 1-based positions in the whole literal (the '[' is offset 0).
    """
    items: list[tuple[str, int]] = []
    pos = 0
    n = len(inner)
    if inner and not inner.strip(" "):
        raise ValueProblem("empty element: write [] for an empty array", 1)
    while True:
        while pos < n and inner[pos] == " ":
            pos += 1
        if pos >= n:  # empty array, or the end after a quoted element
            return items
        ch = inner[pos]
        if ch == ",":
            raise ValueProblem("unexpected ',' (empty element)", pos + 1)
        if ch in ('"', "'"):
            end = pos + 1
            while True:
                end = inner.find(ch, end)
                if end == -1:
                    raise ValueProblem(f"unterminated {ch}-quoted string", pos + 1)
                if inner[end - 1] != "\\":
                    break
                end += 1
            items.append((inner[pos + 1:end].replace("\\" + ch, ch), pos + 2))
            pos = end + 1
            while pos < n and inner[pos] == " ":
                pos += 1
            if pos < n:
                if inner[pos] != ",":
                    raise ValueProblem("expected ',' between array elements", pos + 1)
                pos += 1
                if pos >= n or not inner[pos:].strip(" "):
                    raise ValueProblem("trailing ',' in array", pos)
        else:
            comma = inner.find(",", pos)
            if comma == -1:
                items.append((inner[pos:], pos + 1))
                return items
            items.append((inner[pos:comma], pos + 1))
            pos = comma + 1
            if not inner[pos:].strip(" "):
                raise ValueProblem("trailing ',' in array", pos)
