"""Fill real rclpy messages with boundary values, by walking their type support.

Test-only: reflection is fine here (generated code never does it). Variants:
  "zero"    the class's defaults
  "min"     minimum of every integer, most negative floats, empty sequences, empty text
  "max"     maximum of every integer, full bounded sequences, text at its bound
  "special" NaN, infinities, subnormals, -0.0, non-ASCII and astral-plane text
"""
from __future__ import annotations

import importlib
import math

from rosidl_parser import definition as d

INT_RANGES = {
    "int8": (-2**7, 2**7 - 1), "uint8": (0, 2**8 - 1), "int16": (-2**15, 2**15 - 1),
    "uint16": (0, 2**16 - 1), "int32": (-2**31, 2**31 - 1), "uint32": (0, 2**32 - 1),
    "int64": (-2**63, 2**63 - 1), "uint64": (0, 2**64 - 1), "char": (0, 255),
}
F32_MAX = 3.4028234663852886e38
F64_MAX = 1.7976931348623157e308
F32_SUBNORMAL = 1.401298464324817e-45
F64_SUBNORMAL = 5e-324
VARIANTS = ("zero", "min", "max", "special")


def ros_class(namespaced: d.NamespacedType):
    return getattr(importlib.import_module(".".join(namespaced.namespaces)), namespaced.name)


def fill(cls, variant: str, depth: int = 0):
    msg = cls()
    if variant == "zero":
        return msg
    for (name, _), slot in zip(cls.get_fields_and_field_types().items(), cls.SLOT_TYPES):
        setattr(msg, name, _value(slot, variant, depth, index=0))
    return msg


def _value(t, variant: str, depth: int, index: int):
    if isinstance(t, d.AbstractNestedType):
        elem = t.value_type
        if isinstance(t, d.Array):
            n = t.size
        elif variant == "min":
            n = 0
        elif isinstance(t, d.BoundedSequence):
            n = t.maximum_size
        else:
            n = 3
        values = [_value(elem, variant, depth + 1, k) for k in range(n)]
        return values
    if isinstance(t, d.NamespacedType):
        return fill(ros_class(t), variant, depth + 1)
    if isinstance(t, d.AbstractWString):
        bound = t.maximum_size if isinstance(t, d.BoundedWString) else None
        text = {"min": "", "max": "w" * (bound or 40), "special": "Ωμέγα 𝄞 ☃ 😀"}[variant]
        return text[:bound] if bound is not None else text
    if isinstance(t, d.AbstractString):
        bound = t.maximum_size if isinstance(t, d.BoundedString) else None
        text = {"min": "", "max": "s" * (bound or 40), "special": "héllo ✓ 𝄞"}[variant]
        return text[:bound] if bound is not None else text
    assert isinstance(t, d.BasicType), t
    typename = t.typename
    if typename == "boolean":
        return {"min": False, "max": True, "special": index % 2 == 0}[variant]
    if typename == "octet":
        return bytes([{"min": 0, "max": 255, "special": 0x99}[variant]])
    if typename in ("float", "double"):
        big = F32_MAX if typename == "float" else F64_MAX
        tiny = F32_SUBNORMAL if typename == "float" else F64_SUBNORMAL
        if variant == "min":
            return -big
        if variant == "max":
            return big
        return [math.nan, math.inf, -math.inf, tiny, -0.0, 1.8][index % 6]
    lo, hi = INT_RANGES[typename]
    return {"min": lo, "max": hi, "special": (lo + hi) // 2 + index}[variant]


def normalize(msg, slot=None):
    """A comparable picture of a message: floats by their bits at the field's width (the
    precision the wire and CDR keep), any NaN equal to any other, containers as lists."""
    import struct

    if slot is None or isinstance(slot, d.NamespacedType):
        cls = type(msg)
        return tuple((name, normalize(getattr(msg, name), t))
                     for (name, _), t in zip(cls.get_fields_and_field_types().items(), cls.SLOT_TYPES))
    if isinstance(slot, d.AbstractNestedType):
        return [normalize(v, slot.value_type) for v in msg]
    if isinstance(slot, d.BasicType) and slot.typename in ("float", "double"):
        value = float(msg)
        if math.isnan(value):
            return "nan"
        return struct.pack("<f" if slot.typename == "float" else "<d", value)
    if isinstance(slot, d.BasicType) and slot.typename not in ("boolean", "octet"):
        return int(msg)
    return msg
