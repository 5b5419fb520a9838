"""CBOR primitives shared by every generated codec (wire format sections 3 and 4).

Generated encoders flatten a message into a list of plain Python values (ints, floats,
str, bytes, and bools only where the profile sends CBOR booleans) and call `pack_items`,
which lets cbor2's C encoder write each in its shortest exact form. Generated decoders
call `load_items` and check every item's type and range in straight-line code.

A decoder is total: anything wrong in the input becomes `DecodeError`, nothing else.
"""
from __future__ import annotations

import array
import io
import struct
import sys
from typing import Any, Iterable

import cbor2

_dumps = cbor2.dumps
_loads = cbor2.loads
_load = cbor2.load
_CBORError = cbor2.CBORError
Tag = cbor2.CBORTag

KIND_TOPIC = 0
KIND_REQUEST = 2
KIND_RESPONSE = 3
KINDS = (KIND_TOPIC, KIND_REQUEST, KIND_RESPONSE)
MAX_ID = 255
MAX_SEQ = 0xFFFFFFFFFFFFFFFF
F32_MAX = 3.4028234663852886e+38
INF = float("inf")
# What an rmw_desert receiver can take (wire format section 6).
RMW_MAX_ITEMS = 64
RMW_MAX_TEXT_BYTES = 127


class CodecError(ValueError):
    """A value that cannot be encoded, or bytes that cannot be decoded.

    `path` names the field (`pose.position.x`, `points[3].y`), empty for the payload.
    """

    def __init__(self, path: str, message: str):
        self.path = path
        self.message = message
        super().__init__(f"{path}: {message}" if path else message)


class EncodeError(CodecError):
    """A message that cannot be put on the wire as it is."""


class DecodeError(CodecError):
    """The one error a decoder raises, for any input it cannot take."""


# --- encoding -----------------------------------------------------------------------

# First byte of a CBOR array head -> length of that head.
_HEAD_LEN = {0x98: 2, 0x99: 3, 0x9A: 5, 0x9B: 9}


def pack_items(items: list) -> bytes:
    """Encode `items` as a CBOR sequence: each item in its shortest form, no outer array."""
    try:
        data = _dumps(items, canonical=True)
    except UnicodeEncodeError as exc:
        raise EncodeError("", f"text that UTF-8 cannot carry (a lone surrogate in a string field?): {exc}") from None
    except (_CBORError, TypeError, ValueError) as exc:
        raise EncodeError("", f"cannot encode: {exc}") from None
    return data[_HEAD_LEN.get(data[0], 1):]


def wstring(value: Any, path: str) -> str:
    """A wstring's text as UTF-8 can carry it: lone surrogates are dropped (section 4)."""
    if type(value) is not str:
        raise EncodeError(path, f"expected str for wstring, got {type(value).__name__}")
    try:
        value.encode("utf-8")
        return value
    except UnicodeEncodeError:
        # Pairs of surrogates become their code point; lone ones are dropped.
        return value.encode("utf-16-le", "surrogatepass").decode("utf-16-le", "ignore")


def octets(value: Any, path: str) -> bytes:
    """The bytes of a byte/char/uint8 array: from bytes, a list of 1-byte bytes (rclpy's
    `byte[]`), array.array('B'), a numpy uint8 array or a list of ints 0..255."""
    if type(value) is bytes:
        return value
    try:
        if isinstance(value, (list, tuple)) and value and isinstance(value[0], bytes):
            if any(len(b) != 1 for b in value):
                raise EncodeError(path, "byte array elements must be single bytes")
            return b"".join(value)
        return bytes(value)
    except EncodeError:
        raise
    except (TypeError, ValueError) as exc:
        raise EncodeError(path, f"not an array of bytes 0..255: {exc}") from None


def as_list(value: Any, path: str) -> list | tuple:
    """A sequence field's elements as a list (numpy arrays and array.array included)."""
    if type(value) is list or type(value) is tuple:
        return value
    tolist = getattr(value, "tolist", None)
    if tolist is not None:
        return tolist()
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise EncodeError(path, f"expected a sequence, got {type(value).__name__}")
    return list(value)


_STRUCTS: dict[str, struct.Struct] = {}


def struct_for(code: str, count: int) -> struct.Struct:
    """A cached little-endian struct of `count` values of one `code` (for variable-length
    numeric sequences; fixed layouts are precomputed in generated code)."""
    key = f"<{count}{code}"
    s = _STRUCTS.get(key)
    if s is None:
        if len(_STRUCTS) > 4096:
            _STRUCTS.clear()
        s = _STRUCTS[key] = struct.Struct(key)
    return s


def numbers(st: struct.Struct, values, names: tuple[str, ...] = (), path: str = "") -> tuple:
    """Pack and unpack through `st`: ints are range-checked, float32 rounded to what the
    wire carries, numpy scalars made plain. On failure, say which value broke."""
    try:
        return st.unpack(st.pack(*values))
    except (struct.error, OverflowError, TypeError) as exc:
        raise _number_error(st, tuple(values), names, path, exc) from None


def _number_error(st, values, names, path, exc) -> EncodeError:
    codes = _expand_format(st.format)
    if len(values) != len(codes):
        return EncodeError(path, f"expected {len(codes)} values, got {len(values)}")
    for i, (code, value) in enumerate(zip(codes, values)):
        try:
            struct.pack("<" + code, value)
        except (struct.error, OverflowError, TypeError):
            where = names[i] if names else f"{path}[{i}]"
            return EncodeError(where, f"{value!r} does not fit {_CODE_NAMES.get(code, code)}")
    return EncodeError(path, str(exc))


_CODE_NAMES = {
    "b": "int8", "B": "uint8", "h": "int16", "H": "uint16", "i": "int32", "I": "uint32",
    "q": "int64", "Q": "uint64", "f": "float32", "d": "float64",
}


def _expand_format(fmt: str) -> list[str]:
    out, num = [], ""
    for ch in fmt.lstrip("<"):
        if ch.isdigit():
            num += ch
        else:
            out.extend(ch * int(num or 1))
            num = ""
    return out


def as_bool(value: Any, path: str) -> bool:
    """A bool field's value: True/False, numpy bools, or the integers 0 and 1."""
    if value in (0, 1) and not isinstance(value, (float, str, bytes)):
        return bool(value)
    raise EncodeError(path, f"expected a bool, got {value!r}")


def byte_value(value: Any, path: str) -> int:
    """A `byte` scalar: rclpy holds it as a 1-byte bytes; an int 0..255 is taken too."""
    if type(value) is bytes and len(value) == 1:
        return value[0]
    if type(value) is int and 0 <= value <= 255:
        return value
    raise EncodeError(path, f"expected one byte, got {value!r}")


def bools(values, path: str, cbor_bool: bool) -> list:
    out = []
    for k, value in enumerate(values):
        if value is not True and value is not False:
            value = as_bool(value, f"{path}[{k}]")
        out.append(value if cbor_bool else (1 if value else 0))
    return out


def texts(values, path: str, wide: bool, bound: int | None, max_bytes: int | None) -> list:
    out = []
    for k, value in enumerate(values):
        where = f"{path}[{k}]"
        if wide:
            value = wstring(value, where)
        elif type(value) is not str:
            raise EncodeError(where, f"expected str, got {type(value).__name__}")
        if bound is not None and len(value) > bound:
            raise EncodeError(where, f"{len(value)} characters, over the bound of {bound}")
        if max_bytes is not None and len(value.encode("utf-8", "surrogatepass")) > max_bytes:
            raise EncodeError(where, f"text over {max_bytes} UTF-8 bytes: an rmw_desert receiver overflows")
        out.append(value)
    return out


def under(exc: Exception, path: str, index: int) -> CodecError:
    """Re-raise an element's error with the array element's path in front."""
    prefix = f"{path}[{index}]"
    if isinstance(exc, CodecError):
        inner = f"{prefix}.{exc.path}" if exc.path else prefix
        return type(exc)(inner, exc.message)
    return EncodeError(prefix, f"not a message of the expected type: {exc}")


# --- typed arrays (RFC 8746, wire format section 4.1) ----------------------------------

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


def head_size(value: int) -> int:
    """Bytes of the CBOR head that says `value` (an unsigned integer or a length)."""
    return 1 if value < 24 else 2 if value < 0x100 else 3 if value < 0x10000 else 5 if value < 2**32 else 9


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
        raise _number_error(struct_for(code, len(values)), tuple(values), (), path, exc) from None


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


# --- decoding -----------------------------------------------------------------------

def load_items(payload: bytes) -> list:
    """Decode a CBOR sequence into a list of items, or raise DecodeError.

    cbor2.loads stops at the first top-level break and ignores what follows, so a
    payload holding a 0xFF byte is decoded with a position check instead. (Decoding it
    inside two arrays, 9F 9F payload FF FF, and refusing any result but one element, is
    sound where the payload holds no FF FF and does not end in FF; but looking for those
    costs more than the position check saves: 3.3 against 2.4 us on a LaserScan.)
    """
    if not payload:
        raise DecodeError("", "empty payload")
    if type(payload) is not bytes:      # (`b"\xff" in` a memoryview compares its ints: never true)
        payload = bytes(payload)
    try:
        wrapped = b"".join((b"\x9f", payload, b"\xff"))      # an indefinite array around the items
        if b"\xff" not in payload:
            return _loads(wrapped)
        fp = io.BytesIO(wrapped)
        items = _load(fp)               # (cbor2.load: a CBORDecoder's decode, called from C)
        if fp.tell() != len(payload) + 2:
            raise DecodeError("", "a CBOR break code where an item was expected")
        return items
    except DecodeError:
        raise
    except RecursionError:
        raise DecodeError("", "CBOR nested too deeply") from None
    except (_CBORError, ValueError, TypeError, OverflowError, MemoryError, LookupError) as exc:
        raise DecodeError("", f"not a valid CBOR sequence: {exc}") from None


def peek_header(payload: bytes) -> tuple[int, int]:
    """The kind and id at the start of a payload, without decoding the fields."""
    kind, pos = _peek_uint(payload, 0, "kind")
    ident, _ = _peek_uint(payload, pos, "id")
    if kind not in KINDS:
        raise DecodeError("kind", f"unknown kind {kind} (expected 0, 2 or 3)")
    if not 1 <= ident <= MAX_ID:
        raise DecodeError("id", f"id {ident} out of range 1..255")
    return kind, ident


def _peek_uint(payload: bytes, pos: int, what: str) -> tuple[int, int]:
    """(value, next position) of the unsigned integer at `pos`."""
    if pos >= len(payload):
        raise DecodeError(what, "payload ended before the header")
    head = payload[pos]
    if head < 0x18:
        return head, pos + 1
    if head == 0x18 and pos + 1 < len(payload):
        return payload[pos + 1], pos + 2
    if head == 0x19 and pos + 2 < len(payload):
        return int.from_bytes(payload[pos + 1:pos + 3], "big"), pos + 3
    raise DecodeError(what, f"expected a small unsigned integer, got CBOR byte 0x{head:02x}")


def bad_item(path: str, expected: str, value: Any) -> DecodeError:
    """The error for an item of the wrong type or out of range."""
    if type(value) in (int, float, bool):
        got = repr(value)
    else:
        got = _cbor_kind(value)
    return DecodeError(path, f"expected {expected}, got {got}")


def bad_items(path: str, prim: str, values: list) -> DecodeError:
    """The error for an array whose elements are not all `prim` values: name the first."""
    kind = float if prim in ("float32", "float64") else int
    expected = f"a {prim}" if kind is float else f"an {prim}"
    for k, value in enumerate(values):
        if type(value) is not kind:
            return bad_item(f"{path}[{k}]", expected, value)
    return DecodeError(path, f"an element out of range for {prim}")


def _cbor_kind(value: Any) -> str:
    return {str: "a text string", bytes: "a byte string", list: "an array", dict: "a map",
            type(None): "null"}.get(type(value), type(value).__name__)


def short(path: str) -> DecodeError:
    return DecodeError(path, "payload ended before this field")


def item_bool(value: Any, path: str) -> bool:
    """A bool item: F4/F5, or the unsigned 0/1 of profile native (decoders take both)."""
    if type(value) is int and (value == 0 or value == 1):
        return value == 1
    raise bad_item(path, "a bool (0, 1, false or true)", value)


def item_bools(values: list, path: str) -> list:
    return [v if v is True or v is False else item_bool(v, f"{path}[{k}]") for k, v in enumerate(values)]


def count(v: list, i: int, path: str, bound: int | None, per_elem: int) -> int:
    """A sequence's element count at v[i]: refused when it exceeds its bound or what the
    rest of the payload could hold, before anything is allocated for it."""
    if i >= len(v):
        raise short(path)
    n = v[i]
    if type(n) is not int or n < 0:
        raise bad_item(path, "an element count", n)
    if bound is not None and n > bound:
        raise DecodeError(path, f"{n} elements, over the bound of {bound}")
    if n * per_elem > len(v) - i - 1:
        raise DecodeError(path, f"count {n} exceeds the {len(v) - i - 1} items left in the payload")
    return n


def check_texts(values: list, path: str, bound: int | None) -> None:
    for k, value in enumerate(values):
        if type(value) is not str:
            raise bad_item(f"{path}[{k}]", "a text string", value)
        if bound is not None and len(value) > bound:
            raise DecodeError(f"{path}[{k}]", f"{len(value)} characters, over the bound of {bound}")


def only(values: Iterable, kind: type) -> bool:
    """True when every value is exactly of type `kind` (bool is not an int here)."""
    return set(map(type, values)) <= {kind}


def ints_in(values: list, lo: int, hi: int) -> bool:
    """True when every value is a plain int within lo..hi."""
    return only(values, int) and (not values or (lo <= min(values) and max(values) <= hi))


def float32_ok(values: Iterable) -> bool:
    """True when every float fits float32's range (inf and nan included)."""
    return all(not abs(v) > F32_MAX or abs(v) == INF for v in values)  # NaN passes


def unexpected(type_name: str, exc: Exception) -> DecodeError:
    """The decode error for a failure the generated checks did not foresee (the decoder
    stays total: it never raises anything else)."""
    return DecodeError("", f"cannot decode {type_name}: {type(exc).__name__}: {exc}")
