"""Read and check the `fields:` of a topic (and `request_fields:` / `response_fields:` of
a service): field path -> encoding (wire format section 8).

Every check happens here, at build time, with the manifest's file:line:column: a path
that names no field, an encoding that does not fit the field's type, min >= max, a step
that does not divide the range, a static value or enum value outside the type's range,
a bound looser than the .msg's own, two encodings for one field.
"""
from __future__ import annotations

import re
from fractions import Fraction

import yaml

from uwgen.idl.model import FLOAT_TYPES, INTEGER_RANGES, STRING_TYPES, ArrayKind, FieldType, MessageDef
from uwgen.manifest.model import (
    ENUM, MAX_COUNT, MAX_LENGTH, OMIT, QUANTIZE, STATIC, TIME_OF_DAY, TIME_SINCE_EPOCH, FieldEncoding,
)
from uwgen.manifest.field_values import FieldValues
from uwgen.manifest.nodes import Reader

ENCODING_KEYS = ("min", "max", "precision", "resolution", "out_of_range", "static", "omit", "time",
                 "epoch", "span", "max_length", "max_count", "values")
OUT_OF_RANGE = ("strict", "clamp")
TIME_KINDS = ("day", "epoch")
TIME_TYPE = "builtin_interfaces/msg/Time"
DAY = 86400
F32_MAX = 3.4028234663852886e+38
MAX_CODES = 1 << 64          # an index must fit a CBOR unsigned integer
SEGMENT = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


class FieldsReader:
    """Checks one `fields:` mapping against the message type it encodes."""

    def __init__(self, reader: Reader, lookup):
        self.r = reader
        self.lookup = lookup          # full name -> MessageDef
        self.values = FieldValues(reader)

    def read(self, node: yaml.Node, msg: MessageDef, label: str) -> tuple[FieldEncoding, ...]:
        r = self.r
        if isinstance(node, yaml.ScalarNode) and r.value(node) is None:
            return ()
        entries = r.open_mapping(node, f"fields of {label}")
        out: list[FieldEncoding] = []
        seen: dict[str, tuple[yaml.Node, FieldEncoding]] = {}
        for path, (key_node, value_node) in entries.items():
            ftype, elem = self.resolve(key_node, path, msg, label)
            enc = self.encoding(value_node, path, ftype, elem, f"field {path} of {label}")
            self.no_overlap(key_node, enc, seen)
            seen[path] = (key_node, enc)
            out.append(enc)
        return tuple(out)

    # -- paths -----------------------------------------------------------------------

    def resolve(self, key_node: yaml.Node, path: str, msg: MessageDef, label: str) -> tuple[FieldType, bool]:
        """The type at `path` (the element type when it ends in '[]'), and whether it does."""
        r = self.r
        elem = path.endswith("[]")
        parts = (path[:-2] if elem else path).split(".")
        current: MessageDef = msg
        ftype: FieldType | None = None
        walked: list[str] = []
        for k, part in enumerate(parts):
            if not SEGMENT.fullmatch(part):
                raise r.error(key_node, f"field path '{path}' of {label} is not a dotted path of field names "
                                        "(e.g. pose.position.x, or cell_voltage[] for every element)")
            if ftype is not None:
                if ftype.is_primitive:
                    raise r.error(key_node, f"field path '{path}' of {label}: {'.'.join(walked)} is a {ftype}, "
                                            "which has no fields")
                if ftype.is_array:
                    raise r.error(key_node, f"field path '{path}' of {label}: {'.'.join(walked)} is an array of "
                                            "messages; encodings inside arrays of messages are not supported")
                current = self.lookup(ftype.base)
            names = [f.name for f in current.fields]
            if part not in names:
                known = ", ".join(names) or "none"
                raise r.error(key_node, f"field path '{path}' of {label}: {current.full_name} has no field "
                                        f"'{part}' (its fields: {known})")
            ftype = current.fields[names.index(part)].type
            walked.append(part)
        if elem:
            if not ftype.is_array:
                raise r.error(key_node, f"field path '{path}' of {label}: '[]' needs an array, and "
                                        f"{path[:-2]} is a {ftype}")
            if not ftype.is_primitive:
                raise r.error(key_node, f"field path '{path}' of {label}: encodings inside arrays of messages "
                                        "are not supported")
            return ftype.element(), True
        return ftype, False

    def no_overlap(self, key_node: yaml.Node, enc: FieldEncoding, seen: dict) -> None:
        """One field, one encoding: `a` omitted and `a.b` quantized contradict each other.
        (`x` with max_count and `x[]` for its elements is fine: they say different things.)"""
        for other, (other_node, other_enc) in seen.items():
            a, b = sorted((enc.path, other), key=len)
            covers = b.startswith(a + ".") or (b == a + "[]" and MAX_COUNT not in (enc.kind, other_enc.kind))
            if covers:
                raise self.r.error(key_node, f"field path '{enc.path}' overlaps '{other}' "
                                             f"(line {self.r.where(other_node).line}); give each field one encoding")

    # -- encodings -------------------------------------------------------------------

    def encoding(self, node: yaml.Node, path: str, ftype: FieldType, elem: bool, what: str) -> FieldEncoding:
        r = self.r
        keys = r.mapping(node, what, ENCODING_KEYS)
        where = r.where(node)
        present = set(keys)
        for key in ("omit", "static", "time"):
            if elem and key in keys:
                raise r.error(keys[key][0], f"'{key}' of {what} applies to a whole field: name the array "
                                            f"'{path[:-2]}' without '[]'")

        def alone(key: str, allowed: tuple[str, ...] = ()) -> None:
            extra = present - {key, *allowed}
            if extra:
                other = sorted(extra)[0]
                raise r.error(keys[other][0], f"'{other}' cannot be combined with '{key}' in {what}")

        if "omit" in keys:
            alone("omit")
            value_node = keys["omit"][1]
            if r.value(value_node) is not True:
                raise r.error(value_node, f"omit of {what} must be true (leave the key out to send the field)")
            return FieldEncoding(path, OMIT, where=where)
        if "static" in keys:
            alone("static")
            value = self.values.static_value(keys["static"][1], ftype, what)
            return FieldEncoding(path, STATIC, value=value, where=where)
        if "time" in keys:
            return self.time(keys, path, ftype, elem, what, alone, where)
        if "values" in keys:
            alone("values")
            return self.enum(keys["values"][1], path, ftype, what, where)
        if "max_length" in keys:
            alone("max_length")
            return self.max_length(keys["max_length"][1], path, ftype, what, where)
        if "max_count" in keys:
            alone("max_count")
            return self.max_count(keys["max_count"][1], path, ftype, elem, what, where)
        if "min" in keys or "max" in keys:
            alone("min", ("max", "precision", "resolution", "out_of_range"))
            return self.quantize(keys, node, path, ftype, what, where)
        if present & {"precision", "resolution", "out_of_range"}:
            key = sorted(present)[0]
            raise r.error(keys[key][0], f"'{key}' of {what} needs 'min' and 'max'")
        raise r.error(node, f"{what} says nothing: give min/max (with precision or resolution), static, "
                            "omit, time, values, max_length or max_count")

    def scalar_kind(self, node: yaml.Node, ftype: FieldType, what: str, wanted: str) -> None:
        if ftype.is_array:
            raise self.r.error(node, f"{wanted} of {what} needs a single value, and the field is a {ftype} "
                                     "(write the path with '[]' to encode every element)")
        if not ftype.is_primitive:
            raise self.r.error(node, f"{wanted} of {what} needs a number or string field, and the field is a "
                                     f"{ftype.base} message")

    def quantize(self, keys: dict, node: yaml.Node, path: str, ftype: FieldType, what: str, where) -> FieldEncoding:
        r = self.r
        self.scalar_kind(node, ftype, what, "min/max")
        prim = ftype.base
        if prim not in INTEGER_RANGES and prim not in FLOAT_TYPES or prim == "byte":
            raise r.error(node, f"min/max of {what} need a number field, and the field is a {prim}")
        lo = self.values.decimal(r.require(keys, "min", node, what), f"min of {what}")
        hi = self.values.decimal(r.require(keys, "max", node, what), f"max of {what}")
        if lo >= hi:
            raise r.error(keys["min"][1], f"min of {what} must be below max ({lo} >= {hi})")
        if "precision" in keys and "resolution" in keys:
            raise r.error(keys["resolution"][0], f"{what}: give precision or resolution, not both")
        if "precision" in keys:
            step_node = keys["precision"][1]
            digits = r.integer(step_node, f"precision of {what}", -18, 18)
            step = Fraction(1, 10 ** digits) if digits >= 0 else Fraction(10 ** -digits)
        elif "resolution" in keys:
            step_node = keys["resolution"][1]
            step = self.values.decimal(step_node, f"resolution of {what}")
            if step <= 0:
                raise r.error(step_node, f"resolution of {what} must be > 0, got {step}")
        elif prim in INTEGER_RANGES:
            step_node, step = node, Fraction(1)
        else:
            raise r.error(node, f"{what} is a {prim}: give precision (decimal places) or resolution (step)")
        if (hi - lo) % step:
            raise r.error(step_node, f"the step {step} of {what} does not divide its range {lo}..{hi}; "
                                     "choose min and max on the step's grid")
        if prim in INTEGER_RANGES:
            tlo, thi = INTEGER_RANGES[prim]
            if step.denominator != 1 or lo.denominator != 1:
                raise r.error(step_node, f"{what} is a {prim}: min and the step must be integers")
            if lo < tlo or hi > thi:
                raise r.error(node, f"{what}: {lo}..{hi} is outside the {prim} range {tlo}..{thi}")
        elif prim == "float32" and max(abs(lo), abs(hi)) > F32_MAX:
            raise r.error(node, f"{what}: {lo}..{hi} is outside the float32 range")
        if (hi - lo) / step >= MAX_CODES:
            raise r.error(step_node, f"{what}: {(hi - lo) / step} steps do not fit 64 bits")
        clamp = False
        if "out_of_range" in keys:
            clamp = r.choice(keys["out_of_range"][1], f"out_of_range of {what}", OUT_OF_RANGE) == "clamp"
        return FieldEncoding(path, QUANTIZE, min=lo, max=hi, step=step, clamp=clamp, where=where)

    def enum(self, node: yaml.Node, path: str, ftype: FieldType, what: str, where) -> FieldEncoding:
        r = self.r
        self.scalar_kind(node, ftype, what, "values")
        if ftype.base == "bool":
            raise r.error(node, f"values of {what}: a bool already takes one bit")
        if ftype.base == "byte":
            raise r.error(node, f"values of {what}: a byte field holds an octet, not a number; use uint8 in the .msg")
        items = r.sequence(node, f"values of {what}")
        if len(items) < 1:
            raise r.error(node, f"values of {what} must list at least one value")
        values = []
        for item in items:
            value = self.values.fits(item, ftype, f"a value of {what}")
            if value in values:
                raise r.error(item, f"value {value!r} of {what} is listed twice")
            values.append(value)
        return FieldEncoding(path, ENUM, values=tuple(values), where=where)

    def max_length(self, node: yaml.Node, path: str, ftype: FieldType, what: str, where) -> FieldEncoding:
        r = self.r
        if ftype.base not in STRING_TYPES or ftype.is_array:
            raise r.error(node, f"max_length of {what} needs a string field (or string[] elements with '[]'), "
                                f"and the field is a {ftype}")
        bound = r.integer(node, f"max_length of {what}", 0)
        if ftype.string_bound is not None and bound > ftype.string_bound:
            raise r.error(node, f"max_length {bound} of {what} is looser than the .msg's own bound {ftype.string_bound}")
        return FieldEncoding(path, MAX_LENGTH, bound=bound, where=where)

    def max_count(self, node: yaml.Node, path: str, ftype: FieldType, elem: bool, what: str, where) -> FieldEncoding:
        r = self.r
        if elem or ftype.array not in (ArrayKind.BOUNDED, ArrayKind.UNBOUNDED):
            kind = "a fixed array" if ftype.array is ArrayKind.FIXED else f"a {ftype}"
            raise r.error(node, f"max_count of {what} needs a sequence (T[] or T[<=N]), and the field is {kind}")
        bound = r.integer(node, f"max_count of {what}", 0)
        if ftype.size is not None and bound > ftype.size:
            raise r.error(node, f"max_count {bound} of {what} is looser than the .msg's own bound {ftype.size}")
        return FieldEncoding(path, MAX_COUNT, bound=bound, where=where)

    def time(self, keys: dict, path: str, ftype: FieldType, elem: bool, what: str, alone, where) -> FieldEncoding:
        r = self.r
        node = keys["time"][1]
        kind = r.choice(node, f"time of {what}", TIME_KINDS)
        if ftype.base != TIME_TYPE or ftype.is_array:
            raise r.error(node, f"time of {what} needs a {TIME_TYPE} field, and the field is a {ftype}")
        step = Fraction(1)
        if "resolution" in keys:
            step_node = keys["resolution"][1]
            step = self.values.decimal(step_node, f"resolution of {what}")
            if step <= 0 or (step * 10 ** 9).denominator != 1:
                raise r.error(step_node, f"resolution of {what} must be a positive whole number of nanoseconds")
        if kind == "day":
            alone("time", ("resolution",))
            if Fraction(DAY) % step:
                raise r.error(keys["resolution"][1], f"resolution {step} s of {what} does not divide a day (86400 s)")
            return FieldEncoding(path, TIME_OF_DAY, step=step, where=where)
        alone("time", ("resolution", "epoch", "span"))
        epoch = r.integer(r.require(keys, "epoch", node, what), f"epoch of {what} (unix seconds)", 0, 2 ** 31 - 1)
        span_node = r.require(keys, "span", node, what)
        span = self.values.decimal(span_node, f"span of {what} (seconds)")
        if span <= 0 or span % step:
            raise r.error(span_node, f"span of {what} must be a positive multiple of the resolution {step} s")
        if epoch + span > 2 ** 31 - 1:
            raise r.error(span_node, f"epoch + span of {what} passes the int32 seconds of {TIME_TYPE}")
        return FieldEncoding(path, TIME_SINCE_EPOCH, max=span, step=step, epoch=epoch, where=where)
