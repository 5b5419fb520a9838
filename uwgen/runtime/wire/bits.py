"""Field encodings and bit packing shared by generated codecs (wire format sections 8, 9).

Depends only on the standard library and cbor2's error types through `codec`, so a
generated package can carry it (vendorable). Everything a generated function can know
in advance (a, b, d, nmax, widths) it passes in; these helpers only do the arithmetic.

Quantization is exact: a value v on the grid min = a/d, step = b/d is sent as
n = floor((v - a/d) / (b/d) + 1/2), computed on the exact rational value of the float v
(float.as_integer_ratio), and index n decodes as (a + n*b) / d, a correctly rounded
int/int division: 2.3 at step 0.1 comes back as exactly the float 2.3.

Packed fields are accumulated into one Python int, most significant bits first:
`acc = (acc << width) | value`, starting from a sentinel 1 so leading zeros count;
`to_bytes` pads once at the end. Decoders read from the top with `p`, the number of
bits not yet read: `value = (r >> (p - width)) & mask`.
"""
from __future__ import annotations

import logging
import struct
import time
from collections import Counter
from fractions import Fraction

from uwgen.runtime.wire.codec import F32_MAX, DecodeError, EncodeError

DAY_NS = 86400 * 10 ** 9
NS = 10 ** 9
INT32 = (-0x80000000, 0x7FFFFFFF)

# Values saturated by `out_of_range: clamp`, per field path (read by stats and tests).
CLAMPED: Counter = Counter()
log = logging.getLogger("uwgen.codec")


class WallClock:
    """Where time-of-day decoders read 'now' (unix nanoseconds). Tests replace `now_ns`."""

    def __init__(self):
        self.now_ns = time.time_ns


WALL = WallClock()


# --- quantization -------------------------------------------------------------------

def _real(v, path: str):
    """v as an int or float (numpy scalars included); anything else is refused."""
    if type(v) is float or type(v) is int:
        return v
    if isinstance(v, bool) or isinstance(v, (str, bytes)):
        raise EncodeError(path, f"expected a number, got {v!r}")
    try:
        return float(v)
    except (TypeError, ValueError):
        raise EncodeError(path, f"expected a number, got {type(v).__name__}") from None


def _grid(a: int, b: int, d: int, nmax: int) -> str:
    return f"{float(Fraction(a, d))!r}..{float(Fraction(a + nmax * b, d))!r}"


def quantize(v, a: int, b: int, d: int, nmax: int, clamp: bool, path: str) -> int:
    """The index of v on the grid a/d + k*b/d (k = 0..nmax), rounded half up, exactly."""
    if type(v) is not float and type(v) is not int:
        v = _real(v, path)
    try:
        num, den = v.as_integer_ratio()
    except OverflowError:            # +-inf
        n = -1 if v < 0 else nmax + 1
    except ValueError:               # nan
        raise EncodeError(path, f"NaN has no place on the grid {_grid(a, b, d, nmax)}") from None
    else:
        q = b * den
        n = (2 * (num * d - a * den) + q) // (2 * q)
        if 0 <= n <= nmax:
            return n
    if clamp:
        if not CLAMPED[path]:
            log.warning("%s: %r is outside %s and was clamped (out_of_range: clamp); later ones are only "
                        "counted (uwgen.runtime.wire.bits.CLAMPED)", path, v, _grid(a, b, d, nmax))
        CLAMPED[path] += 1
        return 0 if n < 0 else nmax
    raise EncodeError(path, f"{v!r} is outside {_grid(a, b, d, nmax)} (out_of_range: strict)")


def quantize_all(values, a: int, b: int, d: int, nmax: int, clamp: bool, path: str, fast=None) -> list:
    """Every element's index; `fast` = (min, 1/step, tolerance) allows the float estimate
    where it is provably exact (see ir.Quantized.fast), the exact computation elsewhere."""
    out = []
    if fast is None:
        for k, v in enumerate(values):
            out.append(quantize(v, a, b, d, nmax, clamp, f"{path}[{k}]"))
        return out
    lo, inv, tol = fast
    top = 1.0 - tol
    for k, v in enumerate(values):
        e = (v - lo) * inv if type(v) is float else -1.0
        if 0.0 <= e <= nmax and tol < (e + 0.5) % 1.0 < top:
            out.append(int(e + 0.5))
        else:
            out.append(quantize(v, a, b, d, nmax, clamp, f"{path}[{k}]"))
    return out


def enum_index(v, table: dict, path: str) -> int:
    """The index of v among an enum's values."""
    try:
        n = table.get(v)
    except TypeError:                # unhashable
        n = None
    if n is None or type(v) is bool:
        raise EncodeError(path, f"{v!r} is not one of the values {tuple(table)}")
    return n


def enum_indices(values, table: dict, path: str) -> list:
    return [enum_index(v, table, f"{path}[{k}]") for k, v in enumerate(values)]


def _stamp_ns(stamp, path: str) -> int:
    try:
        sec, nanosec = stamp.sec, stamp.nanosec
    except AttributeError:
        raise EncodeError(path, f"expected a builtin_interfaces/Time, got {type(stamp).__name__}") from None
    if type(sec) is not int or type(nanosec) is not int or not 0 <= nanosec < NS:
        raise EncodeError(path, f"not a valid time: sec={sec!r}, nanosec={nanosec!r}")
    return sec * NS + nanosec


def time_of_day(stamp, step_ns: int, count: int, path: str) -> int:
    """The step index of a Time within its UTC day (rounded half up, wrapping at midnight)."""
    ns = _stamp_ns(stamp, path) % DAY_NS
    return (ns + step_ns // 2) // step_ns % count


def from_time_of_day(n: int, step_ns: int, cls, path: str):
    """The Time within +-12 h of the receiver's clock whose time of day is index n."""
    now = WALL.now_ns()
    t = n * step_ns
    when = now - (now - t) % DAY_NS           # the latest instant <= now with that time of day
    if now - when > DAY_NS // 2:
        when += DAY_NS
    sec, nanosec = divmod(when, NS)
    if not INT32[0] <= sec <= INT32[1]:
        raise DecodeError(path, "the receiver's clock puts this time outside int32 seconds")
    return cls(sec=sec, nanosec=nanosec)


def time_since(stamp, epoch_ns: int, step_ns: int, nmax: int, path: str) -> int:
    """The step index of a Time after the manifest's epoch, 0..nmax."""
    offset = _stamp_ns(stamp, path) - epoch_ns
    n = (2 * offset + step_ns) // (2 * step_ns)
    if not 0 <= n <= nmax:
        raise EncodeError(path, f"time {offset / NS:+.3f} s from the epoch is outside 0..{nmax * step_ns / NS} s")
    return n


def from_time_since(n: int, epoch_ns: int, step_ns: int, cls):
    sec, nanosec = divmod(epoch_ns + n * step_ns, NS)
    return cls(sec=sec, nanosec=nanosec)


# --- bit packing: writing -----------------------------------------------------------

_HALF = struct.Struct(">e")
_SINGLE = struct.Struct(">f")
_DOUBLE = struct.Struct(">d")
FLOAT_TAGS = ((16, _HALF), (32, _SINGLE), (64, _DOUBLE))   # tag 0, 1, 2 (3 is never sent)


def finish(acc: int) -> bytes:
    """The bytes of an accumulator that started at the sentinel 1: padded with zero bits
    to a whole byte, once, at the end."""
    n = acc.bit_length() - 1
    pad = -n % 8
    return ((acc ^ (1 << n)) << pad).to_bytes((n + pad) >> 3, "big")


def put_uint(acc: int, v, width: int, lo: int, hi: int, path: str) -> int:
    """An integer field of range lo..hi as `width` bits of v - lo."""
    if type(v) is not int:
        if isinstance(v, bool) or not hasattr(v, "__index__"):
            raise EncodeError(path, f"expected an integer, got {v!r}")
        v = v.__index__()
    if not lo <= v <= hi:
        raise EncodeError(path, f"{v} is outside {lo}..{hi}")
    return (acc << width) | (v - lo)


def put_varint(acc: int, n: int) -> int:
    """An unbounded count: groups of 8 bits, 7 value bits (least significant first) and
    a high 'more follows' bit."""
    while n >= 0x80:
        acc = (acc << 8) | 0x80 | (n & 0x7F)
        n >>= 7
    return (acc << 8) | n


def put_count(acc: int, n: int, width: int | None) -> int:
    return put_varint(acc, n) if width is None else (acc << width) | n


def put_float(acc: int, v, f32: bool, path: str) -> int:
    """A float as a 2-bit width tag and 16, 32 or 64 bits: the narrowest that gives the
    value back exactly (float32 fields are first rounded to float32, as in native)."""
    if type(v) is not float:
        v = float(_real(v, path))
    if f32:
        try:
            v = _SINGLE.unpack(_SINGLE.pack(v))[0]
        except (OverflowError, struct.error):
            raise EncodeError(path, f"{v!r} does not fit float32") from None
    try:
        h = _HALF.pack(v)
        if v != v or _HALF.unpack(h)[0] == v:
            return (acc << 18) | int.from_bytes(h, "big")
    except OverflowError:
        pass
    s = _SINGLE.pack(v) if f32 or abs(v) <= F32_MAX or v != v else None
    if s is not None and _SINGLE.unpack(s)[0] == v:
        return (((acc << 2) | 1) << 32) | int.from_bytes(s, "big")
    return (((acc << 2) | 2) << 64) | int.from_bytes(_DOUBLE.pack(v), "big")


def put_floats(acc: int, values, f32: bool, path: str) -> int:
    for k, v in enumerate(values):
        acc = put_float(acc, v, f32, f"{path}[{k}]")
    return acc


def put_uints(acc: int, values, width: int, lo: int, hi: int, path: str) -> int:
    for k, v in enumerate(values):
        acc = put_uint(acc, v, width, lo, hi, f"{path}[{k}]")
    return acc


def put_bools(acc: int, values, path: str) -> int:
    for k, v in enumerate(values):
        if v is not True and v is not False:
            if v not in (0, 1) or isinstance(v, (float, str, bytes)):
                raise EncodeError(f"{path}[{k}]", f"expected a bool, got {v!r}")
        acc = (acc << 1) | (1 if v else 0)
    return acc


def put_indices(acc: int, values, width: int) -> int:
    for n in values:
        acc = (acc << width) | n
    return acc


def put_bytes(acc: int, data: bytes, width: int | None) -> int:
    """A length (bit-width `width`, or a varint when unbounded), then the bytes."""
    acc = put_count(acc, len(data), width)
    return (acc << (8 * len(data))) | int.from_bytes(data, "big") if data else acc


def put_text(acc: int, v, width: int | None, path: str) -> int:
    """A string as its UTF-8 bytes with a length prefix (bound checks are the caller's)."""
    try:
        data = v.encode("utf-8")
    except UnicodeEncodeError as exc:
        raise EncodeError(path, f"text that UTF-8 cannot carry: {exc}") from None
    if width is not None and len(data) >> width:
        raise EncodeError(path, f"{len(data)} UTF-8 bytes do not fit the {width}-bit length")
    return put_bytes(acc, data, width)


# --- bit packing: reading -----------------------------------------------------------

def short(path: str) -> DecodeError:
    return DecodeError(path, "packed bits ended before this field")


def get_varint(r: int, p: int, path: str) -> tuple[int, int]:
    n, shift = 0, 0
    while True:
        if p < 8:
            raise short(path)
        p -= 8
        group = (r >> p) & 0xFF
        n |= (group & 0x7F) << shift
        shift += 7
        if not group & 0x80:
            return n, p
        if shift > 63:
            raise DecodeError(path, "a length longer than 64 bits")


def get_count(r: int, p: int, width: int | None, bound: int | None, min_bits: int, path: str) -> tuple[int, int]:
    """A sequence count: refused over its bound or over what the remaining bits can hold."""
    if width is None:
        n, p = get_varint(r, p, path)
    else:
        if p < width:
            raise short(path)
        p -= width
        n = (r >> p) & ((1 << width) - 1)
    if bound is not None and n > bound:
        raise DecodeError(path, f"{n} elements, over the bound of {bound}")
    if n * min_bits > p:
        raise DecodeError(path, f"count {n} exceeds the {p} bits left")
    return n, p


def get_float(r: int, p: int, path: str) -> tuple[float, int]:
    if p < 2:
        raise short(path)
    p -= 2
    tag = (r >> p) & 3
    if tag == 3:
        raise DecodeError(path, "float width tag 3 is not used")
    width, st = FLOAT_TAGS[tag]
    if p < width:
        raise short(path)
    p -= width
    return st.unpack(((r >> p) & ((1 << width) - 1)).to_bytes(width >> 3, "big"))[0], p


def get_floats(r: int, p: int, n: int, f32: bool, path: str) -> tuple[list, int]:
    out = []
    for k in range(n):
        v, p = get_float(r, p, f"{path}[{k}]")
        if f32 and abs(v) > F32_MAX and v not in (float("inf"), float("-inf")):
            raise DecodeError(f"{path}[{k}]", f"expected a float32, got {v!r}")
        out.append(v)
    return out, p


def get_uints(r: int, p: int, n: int, width: int, lo: int, path: str) -> tuple[list, int]:
    if p < n * width:
        raise short(path)
    mask = (1 << width) - 1
    out = []
    for _ in range(n):
        p -= width
        out.append(((r >> p) & mask) + lo)
    return out, p


def get_indices(r: int, p: int, n: int, width: int, nmax: int, path: str) -> tuple[list, int]:
    out, p = get_uints(r, p, n, width, 0, path)
    for k, x in enumerate(out):
        if x > nmax:
            raise DecodeError(f"{path}[{k}]", f"index {x} is over {nmax}")
    return out, p


def get_bools(r: int, p: int, n: int, path: str) -> tuple[list, int]:
    out, p = get_uints(r, p, n, 1, 0, path)
    return [x == 1 for x in out], p


def get_bytes(r: int, p: int, width: int | None, bound: int | None, path: str) -> tuple[bytes, int]:
    n, p = get_count(r, p, width, bound, 8, path)
    p -= 8 * n
    return ((r >> p) & ((1 << (8 * n)) - 1)).to_bytes(n, "big"), p


def get_text(r: int, p: int, width: int | None, bound: int | None, path: str) -> tuple[str, int]:
    data, p = get_bytes(r, p, width, None, path)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DecodeError(path, f"not UTF-8: {exc.reason}") from None
    if bound is not None and len(text) > bound:
        raise DecodeError(path, f"{len(text)} characters, over the bound of {bound}")
    return text, p


def get_texts(r: int, p: int, n: int, width: int | None, bound: int | None, path: str) -> tuple[list, int]:
    out = []
    for k in range(n):
        text, p = get_text(r, p, width, bound, f"{path}[{k}]")
        out.append(text)
    return out, p


def text_width(bound: int | None) -> int | None:
    """Bits of a string's length prefix: room for 4 UTF-8 bytes per character of the bound."""
    return None if bound is None else (4 * bound).bit_length()


def count_width(bound: int | None) -> int | None:
    """Bits of a sequence's count prefix (None: unbounded, a varint)."""
    return None if bound is None else bound.bit_length()


def start(v: list, i: int, path: str) -> tuple[int, int, int]:
    """(r, p, next i) of the packed byte string at v[i]."""
    if i >= len(v):
        raise DecodeError(path, "payload ended before the packed fields")
    data = v[i]
    if type(data) is not bytes:
        raise DecodeError(path, f"expected the byte string of packed fields, got {type(data).__name__}")
    return int.from_bytes(data, "big"), 8 * len(data), i + 1


def end(r: int, p: int, path: str) -> None:
    """Only the final padding (fewer than 8 zero bits) may be left."""
    if p >= 8 or r & ((1 << p) - 1):
        raise DecodeError(path, f"{p} bits left after the last field (padding must be under 8 zero bits)")
