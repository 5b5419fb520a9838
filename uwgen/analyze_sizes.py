"""Sizes of codec IR leaves for `uwgen analyze`: bits in profile packed, bytes in native and
rmw_desert, each as smallest, typical and largest (wire format sections 4, 8, 9).

"Typical" is a stated convention, not a measurement: indices at the middle of their grid,
float32 values that need single precision and float64 values that need double, strings of
TYPICAL_TEXT bytes (or their bound), sequences of TYPICAL_COUNT elements (or their bound).
"Worst" takes every field at its largest; it is None (unbounded) when a string or sequence
has no bound.
"""
from __future__ import annotations

from dataclasses import dataclass

from uwgen.codegen.encodings import (
    Absent, Bool, BoolArray, ByteScalar, Enumerated, Filler, MessageArray, Number, NumberArray, Octets,
    Quantized, Static, Text, TextArray, TimeOfDay, TimeSinceEpoch,
)
from uwgen.codegen.ir import CodecType, IRBuilder
from uwgen.idl.model import ArrayKind
from uwgen.manifest.model import PACKED
from uwgen.runtime.wire.bits import text_width

TYPICAL_TEXT = 8            # bytes of a typical string
TYPICAL_COUNT = 4           # elements of a typical sequence


@dataclass(frozen=True)
class Size:
    """Smallest, typical and largest size of something (largest None: unbounded)."""
    min: int
    typical: int
    max: int | None

    def __add__(self, other: "Size") -> "Size":
        top = None if self.max is None or other.max is None else self.max + other.max
        return Size(self.min + other.min, self.typical + other.typical, top)

    def times(self, lo: int, typ: int, hi: int | None) -> "Size":
        top = None if hi is None or self.max is None else self.max * hi
        return Size(self.min * lo, self.typical * typ, top)


ZERO = Size(0, 0, 0)


def cbor_uint(n: int) -> int:
    """Bytes of CBOR's shortest unsigned integer n."""
    return 1 if n < 24 else 2 if n < 0x100 else 3 if n < 0x10000 else 5 if n < 0x100000000 else 9


def _smaller(a: Size, b: Size) -> Size:
    """The size of whichever of two forms the encoder picks, the smaller each time."""
    top = b.max if a.max is None else a.max if b.max is None else min(a.max, b.max)
    return Size(min(a.min, b.min), min(a.typical, b.typical), top)


def _counts(array: ArrayKind, size: int | None) -> tuple[int, int, int | None]:
    if array is ArrayKind.FIXED:
        return size, size, size
    if array is ArrayKind.BOUNDED:
        return 0, min(size, TYPICAL_COUNT), size
    return 0, TYPICAL_COUNT, None


def _index_max(enc) -> int:
    if isinstance(enc, Enumerated):
        return len(enc.values) - 1
    if isinstance(enc, TimeOfDay):
        return enc.count - 1
    return enc.nmax


def describe(enc) -> str:
    """A short human description of a leaf encoding."""
    if isinstance(enc, Quantized):
        step = (enc.high - enc.low) / enc.nmax
        return f"{float(enc.low):g}..{float(enc.high):g} step {float(step):g}{' clamp' if enc.clamp else ''}"
    if isinstance(enc, Enumerated):
        return f"one of {len(enc.values)} values"
    if isinstance(enc, TimeOfDay):
        return f"time of day, step {enc.step_ns / 1e9:g} s"
    if isinstance(enc, TimeSinceEpoch):
        return f"time since epoch, step {enc.step_ns / 1e9:g} s"
    if isinstance(enc, Static):
        return f"static {enc.value!r}"
    if isinstance(enc, Absent):
        return "not sent"
    if isinstance(enc, Number):
        return enc.prim
    if isinstance(enc, Text):
        return "string" + (f"<={enc.bound}" if enc.bound is not None else "")
    return enc.kind.replace("_", " ")


class Sizer:
    """Sizes of codec IR leaves in bits (packed) or bytes (native, rmw_desert)."""

    def __init__(self, builder: IRBuilder):
        self.builder = builder

    def message(self, ct: CodecType) -> Size:
        total = ZERO
        for leaf in ct.root.leaves():
            total = total + self.leaf(leaf.encoding, ct.profile)
        return total

    def leaf(self, enc, profile: str) -> Size:
        return self.bits(enc) if profile == PACKED else self.bytes(enc, profile)

    # --- packed: bits -------------------------------------------------------------------

    def bits(self, enc) -> Size:
        if isinstance(enc, (Absent, Static)):
            return ZERO
        if isinstance(enc, Filler) or isinstance(enc, Bool):
            return Size(1, 1, 1)
        if isinstance(enc, ByteScalar):
            return Size(8, 8, 8)
        if isinstance(enc, (TimeOfDay, TimeSinceEpoch)):
            return Size(enc.bits, enc.bits, enc.bits)
        if isinstance(enc, Number):
            if enc.is_float:
                return Size(18, 34, 34) if enc.prim == "float32" else Size(18, 66, 66)
            lo, hi = enc.range
            w = (hi - lo).bit_length()
            return Size(w, w, w)
        if isinstance(enc, Text):
            return self._text_bits(enc)
        prefix = self._prefix_bits(enc.array, enc.size) if hasattr(enc, "array") else ZERO
        if isinstance(enc, (Quantized, Enumerated)):
            one = Size(enc.bits, enc.bits, enc.bits)
            if enc.array is ArrayKind.NONE:
                return one
            return prefix + one.times(*_counts(enc.array, enc.size))
        if isinstance(enc, Octets):
            return prefix + Size(8, 8, 8).times(*_counts(enc.array, enc.size))
        if isinstance(enc, NumberArray):
            one = self.bits(Number(enc.prim, enc.code))
        elif isinstance(enc, BoolArray):
            one = Size(1, 1, 1)
        elif isinstance(enc, TextArray):
            one = self._text_bits(enc.text)
        elif isinstance(enc, MessageArray):
            one = self.message(self.builder.by_key(enc.type_key, PACKED))
        else:
            raise AssertionError(enc)
        return prefix + one.times(*_counts(enc.array, enc.size))

    @staticmethod
    def _prefix_bits(array: ArrayKind, size: int | None) -> Size:
        if array is ArrayKind.FIXED:
            return ZERO
        if array is ArrayKind.BOUNDED:
            w = size.bit_length()
            return Size(w, w, w)
        return Size(8, 8, None)    # a varint: 8 bits per 7 bits of count

    @staticmethod
    def _text_bits(enc: Text) -> Size:
        if enc.bound is None:
            return Size(8, 8 + 8 * TYPICAL_TEXT, None)
        w = text_width(enc.bound)
        return Size(w, w + 8 * min(enc.bound, TYPICAL_TEXT), w + 8 * 4 * enc.bound)

    # --- native / rmw_desert: bytes -----------------------------------------------------

    def bytes(self, enc, profile: str) -> Size:
        if isinstance(enc, (Absent, Static)):
            return ZERO
        if isinstance(enc, (Filler, Bool)):
            return Size(1, 1, 1)
        if isinstance(enc, ByteScalar):
            return Size(1, 2, 2)
        if isinstance(enc, (Quantized, Enumerated, TimeOfDay, TimeSinceEpoch)) and \
                getattr(enc, "array", ArrayKind.NONE) is ArrayKind.NONE:
            top = _index_max(enc)
            return Size(1, cbor_uint(top // 2), cbor_uint(top))
        if isinstance(enc, Number):
            if enc.is_float:
                return Size(3, 5, 5) if enc.code == "f" else Size(3, 9, 9)
            lo, hi = enc.range
            return Size(1, 1, cbor_uint(max(hi, -1 - lo)))
        if isinstance(enc, Text):
            return self._text_bytes(enc)
        counts = _counts(enc.array, enc.size)
        count = ZERO if enc.array is ArrayKind.FIXED and not getattr(enc, "fixed_count", False) else \
            Size(1, cbor_uint(counts[1]), None if counts[2] is None else cbor_uint(counts[2]))
        if isinstance(enc, Octets):
            return count + Size(1, 1, 1).times(*counts)
        if isinstance(enc, (Quantized, Enumerated)):
            top = _index_max(enc)
            one = Size(1, cbor_uint(top // 2), cbor_uint(top))
        elif isinstance(enc, NumberArray):
            one = self.bytes(Number(enc.prim, enc.code), profile)
        elif isinstance(enc, BoolArray):
            one = Size(1, 1, 1)
        elif isinstance(enc, TextArray):
            one = self._text_bytes(enc.text)
        elif isinstance(enc, MessageArray):
            one = self.message(self.builder.by_key(enc.type_key, profile))
        else:
            raise AssertionError(enc)
        items = count + one.times(*counts)
        if isinstance(enc, NumberArray) and enc.tag is not None:   # or one typed array (4.1)
            def typed(k: int) -> int:
                return 2 + cbor_uint(enc.width * k) + enc.width * k
            lo, typ, hi = counts
            return _smaller(items, Size(typed(lo), typed(typ), None if hi is None else typed(hi)))
        return items

    @staticmethod
    def _text_bytes(enc: Text) -> Size:
        if enc.bound is None:
            return Size(1, 1 + TYPICAL_TEXT, None)
        top = enc.max_bytes if enc.max_bytes is not None else 4 * enc.bound
        return Size(1, 1 + min(enc.bound, TYPICAL_TEXT), cbor_uint(top) + top)
