"""Lower codec IR to straight-line Python statements.

Each `CodecType` becomes one encoder `enc[_rmw]_<Name>(m, out)`, which appends the
message's CBOR items to `out`, and one decoder `dec[_rmw]_<Name>(v, i, C)`, which reads
items from list `v` at index `i` and returns `(message, next_i)`, building classes from
namespace `C` (rclpy classes or the generated plain ones). Errors name the field path
relative to the type; array loops prefix the element's index on the way out.

Everything that can be decided here is: struct formats, field name tuples, ranges,
bounds and the expression that builds the decoded message. The templates in
`templates/` only place the lines this module returns.

(The decoders are lowered by uwgen.codegen.emit_decode, the shared pieces live in
uwgen.codegen.emit_common.)
"""
from __future__ import annotations

from uwgen.codegen.emit_common import Function, field_access, func_name, not_sent, quantize_lines, slots_name
from uwgen.codegen.emit_decode import Decoding
from uwgen.codegen.encodings import (
    Bool, BoolArray, ByteScalar, ColumnArray, Enumerated, Filler, MessageArray, NumberArray, Octets, Quantized,
    Text, TextArray, TimeOfDay, TimeSinceEpoch,
)
from uwgen.codegen.ir import CodecType, Node, NumberRun, segments
from uwgen.idl.model import ArrayKind


class Lowering(Decoding):
    """Lowers the codec types of one generated module: encoders here, decoders in Decoding."""

    # --- encoder ------------------------------------------------------------------

    def encoder(self, ct: CodecType, slots: bool = False) -> Function:
        """The encoder of `ct`; with `slots`, the one for rclpy messages whose layout
        RosClasses checked: it reads each field's slot, not its property (TypeCodec.encode
        chooses; an AttributeError, a nested value that is no rclpy message, sends it back
        to the encoder that reads fields by name)."""
        body: list[str] = []
        access = field_access(ct.root, body, slots)
        for seg in segments(ct.root):
            if isinstance(seg, NumberRun):
                st = self.consts.struct("<" + "".join(n.encoding.code for n in seg.leaves))
                names = self.consts.names(tuple(n.path for n in seg.leaves))
                values = ", ".join(access(n) for n in seg.leaves)
                body.append(f"out += _numbers({st}, ({values},), {names})")
            else:
                expr = access(seg) if seg.name else ""
                body.extend(self._encode_leaf(seg, seg.encoding, expr, ct.profile_suffix, slots))
        name = func_name("enc", ct.name, ct.suffix)
        if slots:
            return Function(slots_name(name), "m, out",
                            f"enc_{ct.name}{ct.suffix} for rclpy's {ct.full_name}: fields read from their slots.",
                            body or ["pass"])
        return Function(name, "m, out",
                        f"Append the CBOR items of a {ct.full_name} ({ct.profile} profile) to `out`.",
                        body or ["pass"])

    def _encode_leaf(self, leaf: Node, enc, expr: str, suffix: str, slots: bool = False) -> list[str]:
        p = repr(leaf.path)
        if isinstance(enc, Filler):
            return ["out.append(0)  # a message with no fields is one unsigned 0"]
        if (comment := not_sent(leaf, enc)) is not None:
            return [comment]
        if isinstance(enc, TimeOfDay):
            return [f"out.append(_time_of_day({expr}, {enc.step_ns}, {enc.count}, {p}))"]
        if isinstance(enc, TimeSinceEpoch):
            return [f"out.append(_time_since({expr}, {enc.epoch_ns}, {enc.step_ns}, {enc.nmax}, {p}))"]
        if isinstance(enc, Quantized) and enc.array is ArrayKind.NONE:
            return [*quantize_lines(enc, expr, p), "out.append(n)"]
        if isinstance(enc, (Quantized, Enumerated)):
            if isinstance(enc, Quantized):
                args = f"{enc.a}, {enc.b}, {enc.d}, {enc.nmax}, {enc.clamp}, {p}"
                one, many = f"_quantize({{}}, {args})", f"_quantize_all(x, {args}, {enc.fast})"
            else:
                table = self.consts.table(enc.values)
                one, many = f"_enum_index({{}}, {table}, {p})", f"_enum_indices(x, {table}, {p})"
            if enc.array is ArrayKind.NONE:
                return [f"out.append({one.format(expr)})"]
            return [f"x = _as_list({expr}, {p})",
                    *self._length_check(enc.array, enc.size, p, count=enc.array is not ArrayKind.FIXED),
                    f"out += {many}"]
        if isinstance(enc, Bool):
            item = "x" if enc.cbor_bool else "1 if x else 0"
            return [f"x = {expr}",
                    f"if x is not True and x is not False: x = _as_bool(x, {p})",
                    f"out.append({item})"]
        if isinstance(enc, ByteScalar):
            return [f"out.append(_byte_value({expr}, {p}))"]
        if isinstance(enc, Text):
            return [f"x = {expr}", *self._text_checks(enc, p), "out.append(x)"]
        if isinstance(enc, Octets):
            return [f"x = _octets({expr}, {p})", *self._length_check(enc.array, enc.size, p, count=False),
                    "out.append(x)"]
        if isinstance(enc, NumberArray) and enc.tag is not None:
            counted = enc.array is not ArrayKind.FIXED

            def choice(value: str) -> str:
                call = (f"_float32_array({value}, {counted}, {p})" if enc.code == "f"   # rclpy's long float32[]: quicker
                        else f"_number_array({value}, {enc.code!r}, {counted}, {p})")
                return f"out += {call}  # items, or a typed array (tag {enc.tag})"
            checks = self._length_check(enc.array, enc.size, p, count=False)
            if not checks:      # an unbounded sequence: _number_array takes the field's value as it is
                return [choice(expr)]
            return [f"x = _numeric_sequence({expr}, {p})", *checks, choice("x")]
        lines = [f"x = _as_list({expr}, {p})"]
        if isinstance(enc, NumberArray):
            lines += self._length_check(enc.array, enc.size, p, count=enc.array is not ArrayKind.FIXED)
            if enc.array is ArrayKind.FIXED:
                st = self.consts.struct(f"<{enc.size}{enc.code}")
                lines.append(f"out += _numbers({st}, x, (), {p})")
            else:
                lines.append(f"out += _numbers(_struct_for({enc.code!r}, len(x)), x, (), {p})")
            return lines
        if isinstance(enc, BoolArray):
            lines += self._length_check(enc.array, enc.size, p, count=enc.array is not ArrayKind.FIXED)
            lines.append(f"out += _bools(x, {p}, {enc.cbor_bool})")
            return lines
        if isinstance(enc, TextArray):
            counted = enc.array is not ArrayKind.FIXED or enc.fixed_count
            lines += self._length_check(enc.array, enc.size, p, count=counted)
            t = enc.text
            lines.append(f"out += _texts(x, {p}, {t.wide}, {t.bound}, {t.max_bytes})")
            return lines
        if isinstance(enc, ColumnArray):      # by columns (section 4.2)
            lines += self._length_check(enc.array, enc.size, p, count=enc.array is not ArrayKind.FIXED)
            fn = self.ref("enc", enc.type_key, suffix)
            caught = "_struct.error, OverflowError, TypeError, AttributeError"
            if slots:       # an element that is no rclpy message: encode it all by name
                fn, caught = slots_name(fn), "_struct.error, OverflowError, TypeError"
            getters = self.consts.getters(tuple(path for path, _code in enc.columns), slots)
            codes = tuple(code for _path, code in enc.columns)
            lines.append(f"out += _encode_columns(x, {getters}, {codes!r}, {fn}, {p}, ({caught}))")
            return lines
        if isinstance(enc, MessageArray):
            lines += self._length_check(enc.array, enc.size, p, count=enc.array is not ArrayKind.FIXED)
            fn = self.ref("enc", enc.type_key, suffix)
            caught = "_CodecError, AttributeError, TypeError"
            if slots:       # an element that is no rclpy message: encode it all by name
                fn, caught = slots_name(fn), "_CodecError, TypeError"
            lines += ["k = 0",
                      "try:",
                      "    for k, e in enumerate(x):",
                      f"        {fn}(e, out)",
                      f"except ({caught}) as exc:",
                      f"    raise _under(exc, {p}, k) from None"]
            return lines
        raise AssertionError(enc)

    @staticmethod
    def _text_checks(enc: Text, p: str) -> list[str]:
        lines = []
        if enc.wide:
            lines.append(f"x = _wstring(x, {p})")
        else:
            lines.append(f"if type(x) is not str: raise _EncodeError({p}, 'expected str, got ' + type(x).__name__)")
        if enc.bound is not None:
            lines.append(f"if len(x) > {enc.bound}: raise _EncodeError({p}, "
                         f"f'{{len(x)}} characters, over the bound of {enc.bound}')")
        if enc.max_bytes is not None:
            lines.append(f"if len(x) > {enc.max_bytes // 4} and len(x.encode('utf-8', 'surrogatepass')) > {enc.max_bytes}: "
                         f"raise _EncodeError({p}, 'text over {enc.max_bytes} UTF-8 bytes: an rmw_desert receiver overflows')")
        return lines

    @staticmethod
    def _length_check(array: ArrayKind, size: int | None, p: str, count: bool) -> list[str]:
        if array is ArrayKind.FIXED:
            lines = [f"if len(x) != {size}: raise _EncodeError({p}, f'{{len(x)}} elements in a fixed array of {size}')"]
        elif array is ArrayKind.BOUNDED:
            lines = [f"if len(x) > {size}: raise _EncodeError({p}, f'{{len(x)}} elements, over the bound of {size}')"]
        else:
            lines = []
        if count:
            lines.append("out.append(len(x))")
        return lines
