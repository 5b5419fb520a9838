"""Arrays of numeric structs by columns (wire format section 4.2, profile native).

An array of a message type whose every field is a number (Point32, Vector3, Twist) travels
as its count (sequences only), then one column per member: the member's n values as one
byte string, little-endian at the member's width (or as halves, 2 bytes each, for a float
member whose every value is one), or as their n items when that is smaller. The codec IR
chooses this form for such arrays (uwgen.codegen.ir, `ColumnArray`); `encode_columns`
makes each column's choice for encoders, `decode_columns` reads the columns back into the
row-major items the element's decoder takes, so every value is checked as its field's.
"""
from __future__ import annotations

import struct
from typing import Callable

import cbor2

from uwgen.runtime.wire.codec import CodecError, DecodeError, EncodeError, head_size, short, struct_for, under
from uwgen.runtime.wire.typed_arrays import _LONG_ITEM, _from_halves, _halves, _zeros

_dumps = cbor2.dumps
_FLOATS = ("f", "d")
_ONE_BYTE_ITEMS = {"B": bytes(range(24)), "b": bytes(range(24)) + bytes(range(232, 256))}
_WIDTHS = {code: struct.calcsize("<" + code) for code in "bBhHiIqQfd"}   # a member's width


def column(raw: bytes, code: str, n: int) -> bytes | list:
    """One column's form (section 4.2) for its `n` values `raw` (little-endian, struct type
    `code`): halves when every value of a float column is one, else the byte string at the
    member's width when it is no larger than the items, else the items (a list)."""
    w = _WIDTHS[code]
    size = n * w
    typed = head_size(size) + size
    if code in _FLOATS:
        if raw.count(0) == size:              # all 0.0 (a 2-D polygon's z, a quaternion's x)
            return bytes(2 * n)
        if n > 1 and raw == raw[:w] * n:      # one value throughout (a quaternion's w): one check
            half = _halves(raw[:w], code, 1)
            if half is not None:
                return half * n
        low_zeros = raw[0::w].count(0)       # every short float item has its lowest byte 0
        if low_zeros == n and n:
            half = _halves(raw, code, n)
            if half is not None:             # head_size(2n) + 2n <= 3n, the items, for n >= 1
                return half
        short_ = low_zeros
        top = raw[w - 1::w]
        if 0x7F in top or 0xFF in top:       # infinities and NaNs are short items too
            short_ = min(n, low_zeros + top.count(0x7F) + top.count(0xFF))
        if typed <= _LONG_ITEM[code] * (n - short_) + 3 * short_:
            return raw
        zeros = _zeros(raw, code)
        if _LONG_ITEM[code] * (n - zeros) + 3 * zeros < typed:
            return _values(raw, code, n)
    elif typed <= n:                         # an integer item takes one byte at the least
        return raw
    if w == 1:      # a byte whose item is 1 byte long (-24..23) costs 1, any other 2
        items = n + len(raw.translate(None, _ONE_BYTE_ITEMS[code]))
        return raw if typed <= items else _values(raw, code, n)
    values = _values(raw, code, n)
    items = len(_dumps(values, canonical=True)) - head_size(n)
    return raw if typed <= items else values


def _values(raw: bytes, code: str, n: int) -> list:
    """The `n` numbers of little-endian `raw`, of struct type `code`."""
    return list(_struct(code, n).unpack(raw))


def _struct(code: str, n: int) -> struct.Struct:
    """struct_for(code, n), found by one dictionary look-up."""
    st = _STRUCTS.get((code, n))
    if st is None:
        st = struct_for(code, n)
        if len(_STRUCTS) > 4096:
            _STRUCTS.clear()
        _STRUCTS[(code, n)] = st
    return st


_STRUCTS: dict[tuple[str, int], struct.Struct] = {}


def encode_columns(elems, getters: tuple, codes: tuple[str, ...], element: Callable, path: str,
                   caught: tuple) -> list:
    """The items of the columns of `elems` (a list of messages): for each member, read by
    its getter, one byte string or its values. A value that does not fit its member, or an
    element that is not a message (an exception of `caught`), is reported by `element`, the
    element type's own encoder, with the element's path (`points[3].x`)."""
    n = len(elems)
    if not n:
        return []
    try:
        cols = [_struct(code, n).pack(*map(get, elems)) for get, code in zip(getters, codes)]
    except caught as exc:
        raise column_error(elems, element, path, exc) from None
    out: list = []
    for raw, code in zip(cols, codes):
        form = column(raw, code, n)
        if type(form) is bytes:
            out.append(form)
        else:
            out += form
    return out


def column_error(elems, element: Callable, path: str, exc: Exception) -> CodecError:
    """The error of the first element its own encoder refuses."""
    for k, e in enumerate(elems):
        try:
            element(e, [])
        except (CodecError, AttributeError, TypeError) as inner:
            return under(inner, path, k)
    return EncodeError(path, f"cannot encode by columns: {exc}")


def decode_columns(v: list, i: int, n: int, columns: tuple[tuple[str, str], ...], path: str) -> tuple[list, int]:
    """Read the `n`-value columns (section 4.2) at `v[i]`: (the values row-major, as the
    element's decoder reads them, next index). A byte string must hold exactly n values
    (at the member's width, or halves for a float member); items are taken as they are
    (the element's decoder checks each)."""
    k = len(columns)
    if n == 0:
        return [], i
    cols = []
    for member, code in columns:
        if i >= len(v):
            raise short(f"{path}[].{member}")
        item = v[i]
        if type(item) is bytes:
            w = _WIDTHS[code]
            if item.count(0) == len(item) and (len(item) == n * w or code in _FLOATS and len(item) == 2 * n):
                cols.append([0.0 if code in _FLOATS else 0] * n)    # all zeros: no conversion
                i += 1
                continue
            if len(item) == n * w:
                raw = item
            elif code in _FLOATS and len(item) == 2 * n:
                if n > 1 and item == item[:2] * n:      # one value throughout
                    cols.append(_values(_from_halves(item[:2], code, 1), code, 1) * n)
                    i += 1
                    continue
                raw = _from_halves(item, code, n)
            else:
                halves = " or 2 (halves)" if code in _FLOATS else ""
                raise DecodeError(f"{path}[].{member}", f"a column of {len(item)} bytes for {n} values "
                                                        f"of {w}{halves} bytes")
            cols.append(_values(raw, code, n))
            i += 1
        else:
            if len(v) - i < n:
                raise short(f"{path}[].{member}")
            cols.append(v[i:i + n])
            i += n
    rows = [None] * (n * k)
    for j, col in enumerate(cols):
        rows[j::k] = col
    return rows, i
