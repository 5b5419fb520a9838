"""Values the manifest writes for a field (a `static`, a `values` item, min, max and steps),
checked against the field's type with the manifest's file:line:column (wire format section 8):
a bool where a bool goes, a string within its bound, an integer in its type's range, a float32
that float32 holds, and every decimal read exactly as written.
"""
from __future__ import annotations

import math
import struct
from fractions import Fraction

import yaml

from uwgen.idl.model import INTEGER_RANGES, STRING_TYPES, ArrayKind, FieldType
from uwgen.manifest.nodes import Reader


def exact(value) -> Fraction:
    """The decimal number the manifest wrote, exactly: 0.1 -> 1/10 (never 0.1000000000000000055...)."""
    return Fraction(value) if isinstance(value, int) else Fraction(repr(value))


class FieldValues:
    """The value checks `FieldsReader` (uwgen/manifest/fields.py) makes of what a manifest writes."""

    def __init__(self, reader: Reader):
        self.r = reader

    def decimal(self, node: yaml.Node, what: str) -> Fraction:
        value = self.r.value(node, what)
        self.r.expected_number(node, value, what)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.r.error(node, f"{what} must be a finite number, got {self.r.describe(node)}")
        return exact(value)

    def static_value(self, node: yaml.Node, ftype: FieldType, what: str):
        r = self.r
        if not ftype.is_primitive:
            raise r.error(node, f"static of {what}: the field is a {ftype.base} message; give static values "
                                "to its number, bool or string fields (or omit: true for the whole message)")
        if ftype.is_array:
            items = r.sequence(node, f"static of {what}") if not isinstance(node, yaml.ScalarNode) else None
            if items is None:
                raise r.error(node, f"static of {what} must be a list: the field is a {ftype}")
            if ftype.array is ArrayKind.FIXED and len(items) != ftype.size:
                raise r.error(node, f"static of {what} has {len(items)} elements; the field is a {ftype}")
            if ftype.array is ArrayKind.BOUNDED and len(items) > ftype.size:
                raise r.error(node, f"static of {what} has {len(items)} elements, over the bound of {ftype}")
            return tuple(self.fits(item, ftype.element(), f"static of {what}") for item in items)
        return self.fits(node, ftype, f"static of {what}")

    def fits(self, node: yaml.Node, ftype: FieldType, what: str):
        """The value of scalar `node` as field type `ftype` holds it, or a located error."""
        r = self.r
        value = r.value(node, what)
        prim = ftype.base
        if not isinstance(node, yaml.ScalarNode):
            raise r.error(node, f"{what} must be a single value, got {r.describe(node)}")
        if prim == "bool":
            if not isinstance(value, bool):
                raise r.error(node, f"{what} must be true or false for a bool field, got {r.describe(node)}")
            return value
        if prim in STRING_TYPES:
            if not isinstance(value, str):
                raise r.error(node, f"{what} must be a string for a {prim} field, got {r.describe(node)}")
            if ftype.string_bound is not None and len(value) > ftype.string_bound:
                raise r.error(node, f"{what} has {len(value)} characters, over the bound of {ftype}")
            return value
        r.expected_number(node, value, what)     # a plain 0o17 where a number goes
        if prim in INTEGER_RANGES:
            lo, hi = INTEGER_RANGES[prim]
            if isinstance(value, bool) or not isinstance(value, int):
                raise r.error(node, f"{what} must be an integer for a {prim} field, got {r.describe(node)}")
            if not lo <= value <= hi:
                raise r.error(node, f"{what} {value} is outside the {prim} range {lo}..{hi}")
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise r.error(node, f"{what} must be a number for a {prim} field, got {r.describe(node)}")
        value = float(value)
        if prim == "float32" and math.isfinite(value):
            try:
                struct.pack("<f", value)
            except OverflowError:
                raise r.error(node, f"{what} {value} is outside the float32 range") from None
        return value
