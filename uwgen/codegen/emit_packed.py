"""Lower codec IR to straight-line Python for profile `packed` (wire format section 9).

Each packed `CodecType` becomes four functions:
  put_pk_<Name>(m, a) -> a          appends the message's fields to bit accumulator `a`
  get_pk_<Name>(r, p, C) -> (m, p)  reads them from the top `p` bits of int `r`
  enc_pk_<Name>(m, out)             appends the ONE byte string holding all fields
  dec_pk_<Name>(v, i, C)            reads it back from item v[i]
Arrays of messages call the element type's put/get functions, so every field of a
message, nested ones included, is in one bit string padded once at the end.

Widths, masks, offsets and grids are all computed here; `uwgen.runtime.wire.bits` only does
what cannot be written as one expression (floats, strings, loops over arrays).
"""
from __future__ import annotations

from uwgen.codegen.emit import Lowering
from uwgen.codegen.emit_common import (
    F32_MAX, Function, field_access, func_name, index_max, not_read, not_sent, quantize_lines,
)
from uwgen.codegen.encodings import (
    Bool, BoolArray, ByteScalar, Enumerated, Filler, MessageArray, Number, NumberArray, Octets,
    Quantized, Text, TextArray, TimeOfDay, TimeSinceEpoch,
)
from uwgen.codegen.ir import CodecType, Node
from uwgen.idl.model import ArrayKind
from uwgen.runtime.wire.bits import count_width, text_width

FLOAT_MIN_BITS = 18      # a 2-bit tag and a half


def int_width(enc) -> tuple[int, int, int]:
    """(width, lo, hi) of an integer number or number array."""
    lo, hi = (enc.range if isinstance(enc, Number) else enc.elem_range)
    return (hi - lo).bit_length(), lo, hi


def prefix_width(array: ArrayKind, size: int | None) -> int | None:
    """Bits of a sequence's count prefix: from the bound, or None (a varint) when unbounded."""
    return count_width(size) if array is ArrayKind.BOUNDED else None


class PackedLowering(Lowering):
    """Lowers the packed codec types of one generated module."""

    # --- encoder ------------------------------------------------------------------

    def packed_functions(self, ct: CodecType) -> list[Function]:
        s, name = ct.suffix, ct.name
        put, get = func_name("put", name, s), func_name("get", name, s)
        return [
            self.putter(ct),
            self.getter(ct),
            Function(func_name("enc", name, s), "m, out",
                     f"Append the one byte string of a {ct.full_name} (packed profile) to `out`.",
                     [f"out.append(_finish({put}(m, 1)))"]),
            Function(func_name("dec", name, s), "v, i, C",
                     f"Read a {ct.full_name} (packed profile) from items `v` at `i`; return (message, next index).",
                     ["r, p, i = _start(v, i, '')", f"x, p = {get}(r, p, C)", "_end(r, p, '')", "return x, i"]),
        ]

    def putter(self, ct: CodecType) -> Function:
        body: list[str] = []
        access = field_access(ct.root, body)
        for leaf in ct.root.leaves():
            expr = access(leaf) if leaf.name else ""
            body.extend(self._put_leaf(leaf, leaf.encoding, expr, ct.profile_suffix))
        body.append("return a")
        return Function(func_name("put", ct.name, ct.suffix), "m, a",
                        f"Append the fields of a {ct.full_name} to bit accumulator `a` (packed profile).", body)

    def _put_leaf(self, leaf: Node, enc, expr: str, suffix: str) -> list[str]:
        p = repr(leaf.path)
        if isinstance(enc, Filler):
            return ["a <<= 1  # a message with no fields is one 0 bit"]
        if (comment := not_sent(leaf, enc)) is not None:
            return [comment]
        if isinstance(enc, Number):
            if enc.is_float:
                return [f"a = _put_float(a, {expr}, {enc.prim == 'float32'}, {p})"]
            w, lo, hi = int_width(enc)
            off = f" - {lo}" if lo else ""
            return [f"x = {expr}",
                    f"a = (a << {w}) | (x{off}) if type(x) is int and {lo} <= x <= {hi} "
                    f"else _put_uint(a, x, {w}, {lo}, {hi}, {p})"]
        if isinstance(enc, Bool):
            return [f"x = {expr}",
                    f"if x is not True and x is not False: x = _as_bool(x, {p})",
                    "a = (a << 1) | (1 if x else 0)"]
        if isinstance(enc, ByteScalar):
            return [f"a = (a << 8) | _byte_value({expr}, {p})"]
        if isinstance(enc, Text):
            return [f"x = {expr}", *self._text_checks(enc, p), f"a = _put_text(a, x, {text_width(enc.bound)}, {p})"]
        if isinstance(enc, Quantized) and enc.array is ArrayKind.NONE:
            return [*quantize_lines(enc, expr, p), f"a = (a << {enc.bits}) | n"]
        if isinstance(enc, (TimeOfDay, TimeSinceEpoch)) or (
                isinstance(enc, Enumerated) and enc.array is ArrayKind.NONE):
            return [f"a = (a << {enc.bits}) | {self._index_of(enc, expr, p)}"]
        if isinstance(enc, Octets):
            lines = [f"x = _octets({expr}, {p})", *self._length_check(enc.array, enc.size, p, count=False)]
            if enc.array is ArrayKind.FIXED:
                return lines + ([f"a = (a << {8 * enc.size}) | int.from_bytes(x, 'big')"] if enc.size else [])
            return lines + [f"a = _put_bytes(a, x, {prefix_width(enc.array, enc.size)})"]
        lines = [f"x = _as_list({expr}, {p})", *self._length_check(enc.array, enc.size, p, count=False)]
        if enc.array is not ArrayKind.FIXED:
            lines.append(f"a = _put_count(a, len(x), {prefix_width(enc.array, enc.size)})")
        if isinstance(enc, NumberArray):
            if enc.elem_range is None:
                lines.append(f"a = _put_floats(a, x, {enc.prim == 'float32'}, {p})")
            else:
                w, lo, hi = int_width(enc)
                lines.append(f"a = _put_uints(a, x, {w}, {lo}, {hi}, {p})")
        elif isinstance(enc, BoolArray):
            lines.append(f"a = _put_bools(a, x, {p})")
        elif isinstance(enc, TextArray):
            t = enc.text
            lines += [f"for e in _texts(x, {p}, {t.wide}, {t.bound}, None):",
                      f"    a = _put_text(a, e, {text_width(t.bound)}, {p})"]
        elif isinstance(enc, (Quantized, Enumerated)):
            many = self._index_of(enc, "x", p, many=True)
            lines.append(f"a = _put_indices(a, {many}, {enc.bits})")
        elif isinstance(enc, MessageArray):
            fn = self.ref("put", enc.type_key, suffix)
            lines += ["k = 0",
                      "try:",
                      "    for k, e in enumerate(x):",
                      f"        a = {fn}(e, a)",
                      "except (_CodecError, AttributeError, TypeError) as exc:",
                      f"    raise _under(exc, {p}, k) from None"]
        else:
            raise AssertionError(enc)
        return lines

    def _index_of(self, enc, expr: str, p: str, many: bool = False) -> str:
        if isinstance(enc, Quantized):
            fast = f", {enc.fast}" if many else ""
            fn = "_quantize_all" if many else "_quantize"
            return f"{fn}({expr}, {enc.a}, {enc.b}, {enc.d}, {enc.nmax}, {enc.clamp}, {p}{fast})"
        if isinstance(enc, Enumerated):
            fn = "_enum_indices" if many else "_enum_index"
            return f"{fn}({expr}, {self.consts.table(enc.values)}, {p})"
        if isinstance(enc, TimeOfDay):
            return f"_time_of_day({expr}, {enc.step_ns}, {enc.count}, {p})"
        return f"_time_since({expr}, {enc.epoch_ns}, {enc.step_ns}, {enc.nmax}, {p})"

    # --- decoder ------------------------------------------------------------------

    def getter(self, ct: CodecType) -> Function:
        body: list[str] = []
        value_of: dict[str, str] = {}
        counter = [0]
        for leaf in ct.root.leaves():
            enc = leaf.encoding
            if not_read(leaf, enc, body, value_of):
                continue
            counter[0] += 1
            var = f"x{counter[0]}"
            body.extend(self._get_leaf(leaf, enc, var, ct.profile_suffix))
            value_of[leaf.path] = self._ros_value(enc, var)
        self.construct(ct.root, value_of, body, "p")
        return Function(func_name("get", ct.name, ct.suffix), "r, p, C",
                        f"Read a {ct.full_name} from the top `p` bits of `r` (packed profile); "
                        "return (message, bits left).", body)

    @staticmethod
    def _take(var: str, width: int, p: str, lo: int = 0) -> list[str]:
        off = f" + {lo}" if lo else ""
        return [f"if p < {width}: raise _bshort({p})",
                f"p -= {width}",
                f"{var} = ((r >> p) & {hex((1 << width) - 1)}){off}"]

    def _get_leaf(self, leaf: Node, enc, var: str, suffix: str) -> list[str]:
        p = repr(leaf.path)
        if isinstance(enc, Filler):
            return [*self._take(var, 1, p),
                    f"if {var}: raise _DecodeError({p}, 'the 0 bit of an empty message is 1')"]
        if isinstance(enc, Number):
            if enc.is_float:
                lines = [f"{var}, p = _get_float(r, p, {p})"]
                if enc.prim == "float32":
                    lines.append(f"if abs({var}) > {F32_MAX} and abs({var}) != _INF: "
                                 f"raise _bad_item({p}, 'a float32', {var})")
                return lines
            w, lo, _hi = int_width(enc)
            return self._take(var, w, p, lo)
        if isinstance(enc, Bool):
            return [*self._take(var, 1, p), f"{var} = {var} == 1"]
        if isinstance(enc, ByteScalar):
            return self._take(var, 8, p)
        if isinstance(enc, Text):
            return [f"{var}, p = _get_text(r, p, {text_width(enc.bound)}, {enc.bound}, {p})"]
        if isinstance(enc, (TimeOfDay, TimeSinceEpoch)) or (
                isinstance(enc, (Quantized, Enumerated)) and enc.array is ArrayKind.NONE):
            top = index_max(enc)
            lines = self._take(var, enc.bits, p)
            if top < (1 << enc.bits) - 1:
                lines.append(f"if {var} > {top}: raise _DecodeError({p}, f'index {{{var}}} is over {top}')")
            return lines + [f"{var} = {self.index_value(enc, var, p)}"]
        if isinstance(enc, Octets):
            if enc.array is ArrayKind.FIXED:
                return [*self._take(var, 8 * enc.size, p), f"{var} = {var}.to_bytes({enc.size}, 'big')"]
            bound = enc.size if enc.array is ArrayKind.BOUNDED else None
            return [f"{var}, p = _get_bytes(r, p, {prefix_width(enc.array, enc.size)}, {bound}, {p})"]
        if enc.array is ArrayKind.FIXED:
            lines = [f"n = {enc.size}"]
        else:
            bound = enc.size if enc.array is ArrayKind.BOUNDED else None
            lines = [f"n, p = _get_count(r, p, {prefix_width(enc.array, enc.size)}, {bound}, "
                     f"{self._min_bits(enc)}, {p})"]
        if isinstance(enc, NumberArray):
            if enc.elem_range is None:
                lines.append(f"{var}, p = _get_floats(r, p, n, {enc.prim == 'float32'}, {p})")
            else:
                w, lo, _hi = int_width(enc)
                lines.append(f"{var}, p = _get_uints(r, p, n, {w}, {lo}, {p})")
        elif isinstance(enc, BoolArray):
            lines.append(f"{var}, p = _get_bools(r, p, n, {p})")
        elif isinstance(enc, TextArray):
            t = enc.text
            lines.append(f"{var}, p = _get_texts(r, p, n, {text_width(t.bound)}, {t.bound}, {p})")
        elif isinstance(enc, (Quantized, Enumerated)):
            lines += [f"{var}, p = _get_indices(r, p, n, {enc.bits}, {index_max(enc)}, {p})",
                      f"{var} = [{self.index_value(enc, 'e', p)} for e in {var}]"]
        elif isinstance(enc, MessageArray):
            fn = self.ref("get", enc.type_key, suffix)
            lines += [f"{var} = []",
                      "k = 0",
                      "try:",
                      "    for k in range(n):",
                      f"        e, p = {fn}(r, p, C)",
                      f"        {var}.append(e)",
                      "except _DecodeError as exc:",
                      f"    raise _under(exc, {p}, k) from None"]
        else:
            raise AssertionError(enc)
        return lines

    @staticmethod
    def _min_bits(enc) -> int:
        """Fewest bits one element takes (at least 1, so a count never outgrows the input)."""
        if isinstance(enc, NumberArray):
            return FLOAT_MIN_BITS if enc.elem_range is None else max(int_width(enc)[0], 1)
        if isinstance(enc, TextArray):
            return max(text_width(enc.text.bound) or 8, 1)
        if isinstance(enc, (Quantized, Enumerated)):
            return max(enc.bits, 1)
        return 1
