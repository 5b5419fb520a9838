"""Typed arrays (RFC 8746, wire format section 4.1): numeric arrays as one byte string.

In profile native, a numeric array travels as one byte string tagged with its element type
(little-endian elements; float arrays whose every element is a half as float16) whenever
that is no larger than the items; `number_array` and `float32_array` make that choice for
encoders, `typed_array` reads one back for decoders. The CBOR primitives they build on are
in uwgen.runtime.wire.codec.
"""
from __future__ import annotations

import array
import struct
import sys
from typing import Any

import cbor2

from uwgen.runtime.wire.codec import DecodeError, as_list, head_size, number_error, struct_for

_dumps = cbor2.dumps
Tag = cbor2.CBORTag

# struct code -> the RFC 8746 tag of a little-endian typed array of that element type
# (uint8 arrays travel as plain byte strings, section 4).
TYPED_TAGS = {"b": 72, "h": 77, "i": 78, "q": 79, "H": 69, "I": 70, "Q": 71, "f": 85, "d": 86}
HALF_TAG = 84      # float16, little-endian: float arrays whose every element is a half
_LITTLE = sys.byteorder == "little"
# array.array type codes whose items have the struct code's width here (all of them on the
# platforms ROS 2 runs on); any other goes through struct.
_ARRAY_OK = {c for c in TYPED_TAGS if array.array(c).itemsize == struct.calcsize("<" + c)}
_LONG_ITEM = {"f": 5, "d": 9}   # bytes of a float item that is not short
# struct code -> (kind, itemsize) of the numpy dtype that holds exactly such values
_NUMPY_KINDS = {c: ("f" if c in "fd" else "i" if c.islower() else "u", struct.calcsize("<" + c)) for c in TYPED_TAGS}
_WIDTHS = {c: struct.calcsize("<" + c) for c in TYPED_TAGS}



def numeric_sequence(value: Any, path: str):
    """A numeric array field as it is (list, tuple, array.array, numpy array), else as a list."""
    if type(value) in (list, tuple, array.array) or hasattr(value, "dtype"):
        return value
    return as_list(value, path)


def number_array(value, code: str, counted: bool, path: str) -> list:
    """The items of a numeric array (profile native, section 4.1): one typed array, a byte
    string tagged TYPED_TAGS[code] holding the elements little-endian, when that is no
    larger than the items; else the items, after a count when `counted`. Every value is
    range-checked (and float32 rounded) as its field's type requires. `value` is the
    field's value as it is (list, tuple, array.array, numpy array, or another sequence).

    The items' size is bounded first at memory speed (floats: at least the long form for
    every value that cannot be short, at most the long form for every value but zeros) and
    measured only when the bounds do not decide."""
    if type(value) is array.array and value.typecode == code and _LITTLE and code in _ARRAY_OK:
        raw = value.tobytes()            # rclpy's numeric sequences: the elements as they are
    else:
        raw = _little_endian(value, code, path)
    size = len(raw)
    if size <= CHOICE_CACHE_BYTES:       # small arrays repeat (covariances): decide once each
        key = (code, counted, raw)
        hit = _CHOICES.get(key)
        if hit is None:
            if len(_CHOICES) >= CHOICE_CACHE_SIZE:
                _CHOICES.clear()
            hit = _CHOICES[key] = _choose(raw, code, counted)
        return hit
    return _choose(raw, code, counted)


def float32_array(value, counted: bool, path: str) -> list:
    """number_array(value, "f", counted, path), reached with less work for the long
    float32 sequences rclpy holds as array.array('f') (a LaserScan's ranges): the same
    choice, and where these quick tests do not decide, number_array's own steps."""
    n = len(value) if type(value) is array.array and value.typecode == "f" else 0
    if n * 4 <= CHOICE_CACHE_BYTES or not _LITTLE:
        return number_array(value, "f", counted, path)
    raw = value.tobytes()
    low_zeros = raw[0::4].count(0)
    if low_zeros == n:                       # maybe all halves (then H < I: n > 128)
        np = _numpy()
        if np is not None and _normal_halves(raw):
            return [Tag(HALF_TAG, np.frombuffer(raw, _DTYPES["f"]).astype(_DTYPES["e"]).tobytes())]
        return _choose(raw, "f", counted)
    top = raw[3::4]
    short = low_zeros + (top.count(0x7F) + top.count(0xFF) if 0x7F in top or 0xFF in top else 0)  # as in _choose
    if 2 + head_size(4 * n) + 4 * n <= (head_size(n) if counted else 0) + 5 * n - 2 * short:
        return [Tag(TYPED_TAGS["f"], raw)]
    return _choose(raw, "f", counted)


CHOICE_CACHE_BYTES = 512       # arrays up to this many bytes have their choice remembered,
CHOICE_CACHE_SIZE = 1024       # this many of them (a few MiB at most), then forgotten
_CHOICES: dict[tuple[str, bool, bytes], list] = {}


def _choose(raw: bytes, code: str, counted: bool) -> list:
    """number_array's choice for the little-endian elements `raw` (a new list; callers copy it)."""
    size = len(raw)
    w = _WIDTHS[code]
    n = size // w
    typed = 2 + head_size(size) + size
    count = head_size(n) if counted else 0
    if code in _LONG_ITEM:
        # At least as many values as could be short items (half for float32 values, half
        # or single for float64 ones), counted at memory speed: such a value has its
        # lowest byte 0, or it is an infinity or a NaN (top byte 0x7F or 0xFF). Every
        # half has its lowest byte 0: only when all do can the array be all halves.
        short = low_zeros = raw[0::w].count(0)
        if low_zeros == n and n:           # maybe all halves: 2 bytes each, items take 3
            half = _halves(raw, code, n)
            if half is not None:
                if 2 + head_size(2 * n) + 2 * n <= count + 3 * n:
                    return [Tag(HALF_TAG, half)]
                values = _values(raw, code)
                return [n, *values] if counted else values
        else:
            top = raw[w - 1::w]
            if 0x7F in top or 0xFF in top:     # (a quick look first: rare in sensor data)
                short = min(n, low_zeros + top.count(0x7F) + top.count(0xFF))
        if typed <= count + _LONG_ITEM[code] * (n - short) + 3 * short:
            return [Tag(TYPED_TAGS[code], raw)]
        zeros = _zeros(raw, code)
        if count + _LONG_ITEM[code] * (n - zeros) + 3 * zeros < typed:
            values = _values(raw, code)
            return [n, *values] if counted else values
    elif typed <= count + n:               # one byte per integer at the very least
        return [Tag(TYPED_TAGS[code], raw)]
    values = _values(raw, code)            # measure the items
    if typed > len(_dumps([n, *values] if counted else values, canonical=True)) - head_size(n + counted):
        return [n, *values] if counted else values
    return [Tag(TYPED_TAGS[code], raw)]


def _little_endian(value, code: str, path: str) -> bytes:
    """The elements of `value` as `code` values, little-endian, or EncodeError."""
    if type(value) is array.array and value.typecode == code and code in _ARRAY_OK:
        if _LITTLE:
            return value.tobytes()
        swapped = array.array(code, value)
        swapped.byteswap()
        return swapped.tobytes()
    dtype = getattr(value, "dtype", None)
    if dtype is not None and (dtype.kind, dtype.itemsize) == _NUMPY_KINDS[code] and dtype.isnative \
            and _LITTLE and getattr(value, "ndim", 0) == 1:
        return value.tobytes()
    values = as_list(value, path)
    try:
        return struct_for(code, len(values)).pack(*values)
    except (struct.error, OverflowError, TypeError) as exc:
        raise number_error(struct_for(code, len(values)), tuple(values), (), path, exc) from None


def _values(raw: bytes, code: str) -> list:
    """The numbers of little-endian `raw`, elements of struct type `code`."""
    if code in _ARRAY_OK and _LITTLE:
        out = array.array(code)
        out.frombytes(raw)
        return out.tolist()
    return list(struct.unpack(f"<{len(raw) // _WIDTHS[code]}{code}", raw))


def _numpy():
    """numpy when it is installed (it is wherever rclpy is), else None: half-precision
    conversions then go through struct, slower."""
    global _np
    if _np is False:
        try:
            import numpy as _np
        except ImportError:
            _np = None
        else:       # dtype objects, not strings: numpy parses a string at every call
            _DTYPES.update((code, _np.dtype(name)) for code, name in (("e", "<f2"), *_HALF_OF.items()))
    return _np


_np = False
NUMPY_FROM = 48    # elements: below, struct converts faster than numpy's call overhead
_HALF_OF = {"f": "<f4", "d": "<f8"}
_DTYPES: dict = {}  # struct code -> numpy dtype, little-endian ("e": half), once numpy is imported


# Bytes that may be, in every element of a float32 array, the second byte (mantissa bits
# 8-15: the low 5 must be 0) and the top byte (sign and exponent bits 1-7: exponent 114-141)
# of a float32 that is a normal half (wire format 4.1), with the lowest byte 0.
_HALF_MANTISSA_BYTES = bytes(b for b in range(256) if b & 0x1F == 0)
_HALF_NORMAL_TOPS = bytes(b for b in range(256) if 57 <= b & 0x7F <= 70)


def _normal_halves(raw: bytes) -> bool:
    """True when every element of float32 array `raw` (little-endian, whose lowest bytes
    are all 0) is a normal half-precision number, |x| in [2**-13, 2**15) with no mantissa
    bit below half's 10: then it converts to half exactly, with no floating point
    exception, and needs no check back. (Not all halves pass: zeros, infinities, NaNs,
    subnormals and the ends of half's range take _halves' checked conversion.)"""
    return not raw[1::4].translate(None, _HALF_MANTISSA_BYTES) and not raw[3::4].translate(None, _HALF_NORMAL_TOPS)


def _halves(raw: bytes, code: str, n: int) -> bytes | None:
    """`raw` (`n` float elements, little-endian, whose lowest bytes are all 0, as every
    half's is) as half-precision floats, when every element converts to half and back
    bit for bit; else None."""
    np = _numpy() if n > NUMPY_FROM else None
    if np is not None and code == "f" and _normal_halves(raw):
        return np.frombuffer(raw, _DTYPES["f"]).astype(_DTYPES["e"]).tobytes()
    if np is not None:
        wide = np.frombuffer(raw, _DTYPES[code])
        with np.errstate(all="ignore"):
            half = wide.astype(_DTYPES["e"])
        return half.tobytes() if half.astype(_DTYPES[code]).tobytes() == raw else None
    halves = struct_for("e", n)
    try:
        half = halves.pack(*_values(raw, code))
    except (OverflowError, struct.error):
        return None
    return half if struct_for(code, n).pack(*halves.unpack(half)) == raw else None


def _from_halves(raw: bytes, code: str, n: int) -> bytes:
    """`n` half-precision elements (little-endian) widened to `code` floats, little-endian."""
    np = _numpy() if n > NUMPY_FROM else None
    if np is not None:
        return np.frombuffer(raw, _DTYPES["e"]).astype(_DTYPES[code]).tobytes()
    return struct_for(code, n).pack(*struct_for("e", n).unpack(raw))


def _zeros(raw: bytes, code: str) -> int:
    """How many elements of float array `raw` are 0.0 or -0.0 (short items: F9 00 00)."""
    ints = memoryview(raw).cast("I" if code == "f" else "Q").tolist()
    return ints.count(0) + ints.count(1 << (8 * _WIDTHS[code] - 1))


def typed_array(item: Tag, code: str, path: str, size: int | None, fixed: bool) -> array.array:
    """The elements of a typed array item (section 4.1) read for a field of element type
    `code`: `size` is the fixed length or the bound (None: unbounded)."""
    raw = item.value
    half = item.tag == HALF_TAG and code in _HALF_OF      # halves, for floats
    if type(raw) is not bytes or not (half or item.tag == TYPED_TAGS[code]):
        raise DecodeError(path, f"expected a typed array (tag {TYPED_TAGS[code]} or, for floats, {HALF_TAG}, "
                                f"on a byte string), got tag {item.tag}")
    w = 2 if half else _WIDTHS[code]
    n, odd = divmod(len(raw), w)
    if odd:
        raise DecodeError(path, f"a typed array of {len(raw)} bytes is not a whole number of {w}-byte elements")
    if fixed and n != size:
        raise DecodeError(path, f"{n} elements in a fixed array of {size}")
    if size is not None and n > size:
        raise DecodeError(path, f"{n} elements, over the bound of {size}")
    if half:
        raw = _from_halves(raw, code, n)
    if code not in _ARRAY_OK:
        return list(struct.unpack(f"<{n}{code}", raw))
    out = array.array(code, raw)
    if not _LITTLE:
        out.byteswap()
    return out
