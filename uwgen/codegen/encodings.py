"""The leaf encodings of the codec IR: how one field (a scalar or a whole array) is written.

Each is a frozen dataclass whose `kind` selects its lowering in uwgen.codegen.emit and
emit_decode (and uwgen.codegen.emit_packed); the ones built from a manifest's field encodings (wire format
section 8) carry everything precomputed. The tree that holds them and the builder are in
uwgen.codegen.ir.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import struct
from fractions import Fraction

from uwgen.idl.model import INTEGER_RANGES, OCTET_TYPES, ArrayKind, FieldType
from uwgen.manifest.model import (
    ENUM, OMIT, QUANTIZE, STATIC, TIME_OF_DAY, TIME_SINCE_EPOCH, FieldEncoding,
)

STRUCT_CODES = {
    "int8": "b", "uint8": "B", "char": "B", "int16": "h", "uint16": "H",
    "int32": "i", "uint32": "I", "int64": "q", "uint64": "Q",
    "float32": "f", "float64": "d",
}


# --- leaf encodings ------------------------------------------------------------------
# Each says how one field (a scalar or a whole array) is written; `kind` selects the
# lowering in uwgen.codegen.emit and emit_decode.

@dataclass(frozen=True)
class Number:
    """An integer or float scalar. Consecutive numbers are packed through one struct."""
    prim: str
    code: str            # struct code; float64 narrowed to 'f' in rmw_desert
    kind: str = "number"

    @property
    def is_float(self) -> bool:
        return self.prim in ("float32", "float64")

    @property
    def range(self) -> tuple[int, int] | None:
        return INTEGER_RANGES.get(self.prim)


@dataclass(frozen=True)
class Bool:
    cbor_bool: bool      # True: F4/F5 (rmw_desert); False: unsigned 0/1 (native)
    kind: str = "bool"


@dataclass(frozen=True)
class ByteScalar:
    """A `byte` (octet) scalar: an unsigned item; rclpy holds it as 1-byte bytes."""
    kind: str = "byte"


@dataclass(frozen=True)
class Text:
    wide: bool                  # wstring: lone surrogates dropped
    bound: int | None           # string<=N (characters)
    max_bytes: int | None       # rmw_desert: the receiver overflows above 127 bytes
    kind: str = "text"


@dataclass(frozen=True)
class Octets:
    """A byte/char/uint8 array as one CBOR byte string (native profile)."""
    array: ArrayKind
    size: int | None
    elem: str                   # byte, char or uint8: decides the rclpy container
    kind: str = "octets"


@dataclass(frozen=True)
class NumberArray:
    """An array of integers or floats: its items (after a count for sequences), or, where
    `tag` is set (profile native, wire format section 4.1), one RFC 8746 typed array
    (byte string tagged `tag`) whenever that is no larger than the items."""
    prim: str
    code: str
    array: ArrayKind
    size: int | None
    elem_range: tuple[int, int] | None
    tag: int | None = None
    kind: str = "number_array"

    @property
    def width(self) -> int:
        """Bytes of one element in a typed array."""
        return struct.calcsize("<" + self.code)


@dataclass(frozen=True)
class BoolArray:
    array: ArrayKind
    size: int | None
    cbor_bool: bool
    kind: str = "bool_array"


@dataclass(frozen=True)
class TextArray:
    array: ArrayKind
    size: int | None
    text: Text
    fixed_count: bool           # rmw_desert writes a count even for fixed string arrays
    kind: str = "text_array"


@dataclass(frozen=True)
class MessageArray:
    array: ArrayKind
    size: int | None
    type_key: str               # CodecType.key of the element type
    elem_min_items: int
    elem_fixed_items: int | None
    elem_min_bytes: int
    kind: str = "message_array"


@dataclass(frozen=True)
class ColumnArray(MessageArray):
    """An array of a message type whose every field is a number, nested messages flattened
    (Point32, Vector3, Twist): profile native sends it by columns (wire format section 4.2),
    the count once (sequences), then each member's n values as one byte string
    (little-endian at the member's width, or halves for a float member whose every value
    is one) or as its n items, whichever is smaller. `columns` are the members in field
    order: (path within the element, struct code)."""
    columns: tuple[tuple[str, str], ...] = ()
    kind: str = "column_array"

    @property
    def row_width(self) -> int:
        """Bytes of one element with every column at its width."""
        return sum(struct.calcsize("<" + code) for _path, code in self.columns)


@dataclass(frozen=True)
class Absent:
    """Not on the wire (rmw_desert drops byte fields); decoders leave the default."""
    why: str
    kind: str = "absent"


@dataclass(frozen=True)
class Filler:
    """The single unsigned 0 that stands for a message with no fields."""
    kind: str = "filler"


# --- field encodings from the manifest (wire format section 8) -----------------------
# Everything is precomputed here: the decoder's value is (a + n*b) / d with integers.

@dataclass(frozen=True)
class Quantized:
    """A number on the grid min, min+step, ..., max, sent as the index n (0..nmax).
    The value of index n is exactly (a + n*b) / d (min = a/d, step = b/d)."""
    prim: str
    a: int
    b: int
    d: int
    nmax: int
    clamp: bool = field(metadata={"schema": False})   # the sender's choice; the bytes mean the same
    array: ArrayKind = ArrayKind.NONE    # cell_voltage[]: every element on the grid
    size: int | None = None
    kind: str = "quantized"

    @property
    def bits(self) -> int:
        return self.nmax.bit_length()

    @property
    def is_float(self) -> bool:
        return self.prim in ("float32", "float64")

    @property
    def fast(self) -> tuple[float, float, float] | None:
        """(min, 1/step, tolerance) for the float estimate e = (v - min) * (1/step) of the
        index, or None where floats cannot estimate it. |e - exact| < tolerance, so
        int(e + 0.5) is the exact answer unless e + 0.5 is within tolerance of an integer;
        encoders check that and fall back to the exact integer computation."""
        if not self.is_float:
            return None
        tol = (abs(Fraction(self.a, self.b)) + self.nmax + 1) * Fraction(1, 2 ** 49) + Fraction(1, 2 ** 40)
        if tol > Fraction(1, 64):
            return None
        return float(Fraction(self.a, self.d)), float(Fraction(self.d, self.b)), float(tol)

    @property
    def low(self) -> Fraction:
        return Fraction(self.a, self.d)

    @property
    def high(self) -> Fraction:
        return Fraction(self.a + self.nmax * self.b, self.d)


@dataclass(frozen=True)
class Enumerated:
    """One of `values`, sent as its index."""
    prim: str
    values: tuple
    array: ArrayKind = ArrayKind.NONE
    size: int | None = None
    kind: str = "enum"

    @property
    def bits(self) -> int:
        return (len(self.values) - 1).bit_length()


@dataclass(frozen=True)
class Static:
    """Not sent: the decoder fills `value` (a Python literal of the field's type)."""
    value: object
    octets: str | None = None    # 'byte' / 'uint8' arrays: how the value is held
    kind: str = "static"


@dataclass(frozen=True)
class TimeOfDay:
    """A builtin_interfaces/Time as the step index within its UTC day; the receiver puts
    it back within +-12 h of its own clock."""
    step_ns: int
    count: int                   # indices per day: 86400 s / step
    class_key: str
    kind: str = "time_of_day"

    @property
    def bits(self) -> int:
        return (self.count - 1).bit_length()


@dataclass(frozen=True)
class TimeSinceEpoch:
    """A builtin_interfaces/Time as the step index after `epoch_ns` (0..nmax)."""
    epoch_ns: int
    step_ns: int
    nmax: int
    class_key: str
    kind: str = "time_since_epoch"

    @property
    def bits(self) -> int:
        return self.nmax.bit_length()


Encoding = (Number | Bool | ByteScalar | Text | Octets | NumberArray | BoolArray | TextArray
            | MessageArray | ColumnArray | Absent | Filler | Quantized | Enumerated | Static | TimeOfDay
            | TimeSinceEpoch)

TIME_TYPE = "builtin_interfaces/msg/Time"


def type_key(full_name: str) -> str:
    """The unique Python-safe name of a type: 'geometry_msgs__Twist'."""
    pkg, _ns, name = full_name.split("/")
    return f"{pkg}__{name}"


def field_encoding(fe: FieldEncoding, ftype: FieldType, array: ArrayKind = ArrayKind.NONE,
                   size: int | None = None) -> Encoding:
    """The IR node of a manifest field encoding on a field of type `ftype` (the element
    type when `array` says the encoding applies to every element)."""
    if fe.kind == OMIT:
        return Absent("omitted by the manifest; the receiver keeps the default")
    if fe.kind == STATIC:
        octets = ftype.base if ftype.is_array and ftype.base in OCTET_TYPES else None
        value = list(fe.value) if isinstance(fe.value, tuple) else fe.value
        if ftype.base == "byte" and not ftype.is_array:
            value = bytes((value,))
        return Static(value, octets)
    if fe.kind == QUANTIZE:
        d = fe.min.denominator * fe.step.denominator // _gcd(fe.min.denominator, fe.step.denominator)
        a, b = int(fe.min * d), int(fe.step * d)
        return Quantized(ftype.base, a, b, d, fe.count - 1, fe.clamp, array, size)
    if fe.kind == ENUM:
        return Enumerated(ftype.base, tuple(fe.values), array, size)
    step_ns = int(fe.step * 10 ** 9)
    if fe.kind == TIME_OF_DAY:
        return TimeOfDay(step_ns, fe.count, type_key(TIME_TYPE))
    if fe.kind == TIME_SINCE_EPOCH:
        return TimeSinceEpoch(fe.epoch * 10 ** 9, step_ns, fe.count - 1, type_key(TIME_TYPE))
    raise AssertionError(fe.kind)


def _gcd(x: int, y: int) -> int:
    while y:
        x, y = y, x % y
    return x
