"""Lower codec IR to straight-line Python statements.

Each `CodecType` becomes one encoder `enc[_rmw]_<Name>(m, out)`, which appends the
message's CBOR items to `out`, and one decoder `dec[_rmw]_<Name>(v, i, C)`, which reads
items from list `v` at index `i` and returns `(message, next_i)`, building classes from
namespace `C` (rclpy classes or the generated plain ones). Errors name the field path
relative to the type; array loops prefix the element's index on the way out.

Everything that can be decided here is: struct formats, field name tuples, ranges,
bounds and the expression that builds the decoded message. The templates in
`templates/` only place the lines this module returns.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

from uwgen.codegen.encodings import (
    Absent, Bool, BoolArray, ByteScalar, Enumerated, Filler, MessageArray, Number, NumberArray, Octets,
    Quantized, Static, Text, TextArray, TimeOfDay, TimeSinceEpoch,
)
from uwgen.codegen.ir import CodecType, Node, NumberRun, segments
from uwgen.idl.model import ArrayKind

F32_MAX = "3.4028234663852886e+38"
# A decoder builds its message in one expression, `C.A(b=C.B(c=...))`, one pair of
# parentheses per nesting level; Python's parser refuses more than 200 nested ones
# ("too many nested parentheses"). Every NEST_CHUNK levels the inner message is built
# into a local first, so no expression nests deeper, whatever the type's depth.
NEST_CHUNK = 32


@dataclass
class Constants:
    """Module-level constants the functions of one module share (structs, name tuples)."""
    lines: list[str] = field(default_factory=list)
    _names: dict[str, str] = field(default_factory=dict)

    def struct(self, fmt: str) -> str:
        return self._add(f"_struct.Struct({fmt!r})", "_S")

    def names(self, names: tuple[str, ...]) -> str:
        return self._add(repr(names), "_N")

    def values(self, values: tuple) -> str:
        """An enum's values, by index."""
        return self._add(repr(tuple(values)), "_V")

    def table(self, values: tuple) -> str:
        """An enum's value -> index table."""
        return self._add(repr({v: k for k, v in enumerate(values)}), "_E")

    def _add(self, expr: str, prefix: str) -> str:
        name = self._names.get(expr)
        if name is None:
            name = f"{prefix}{len(self._names)}"
            self._names[expr] = name
            self.lines.append(f"{name} = {expr}")
        return name


@dataclass
class Function:
    name: str
    args: str
    doc: str
    body: list[str]


def module_alias(module: str) -> str:
    """How one generated module imports another: 'geometry_msgs.msg' -> '_geometry_msgs_msg'."""
    return "_" + module.replace(".", "_")


def func_name(kind: str, ct_key_name: str, suffix: str) -> str:
    return f"{kind}{suffix}_{ct_key_name}"


def slots_name(encoder: str) -> str:
    """The name of the encoder that reads rclpy's slots, beside `encoder`."""
    return f"{encoder}_slots"


def field_access(root: Node, body: list[str], slots: bool = False) -> Callable[[Node], str]:
    """Name each nested message of `root` once (`m1 = m.linear`, appended to `body`) and
    return how a leaf is read: `access(leaf) -> 'm1.x'`; with `slots`, rclpy's slot behind
    each field's property is read instead (`m1._x`)."""
    var_of = {"": "m"}
    prefix = "_" if slots else ""

    def access(node: Node) -> str:
        parent = node.path.rsplit(".", 1)[0] if "." in node.path else ""
        return f"{var_of[parent]}.{prefix}{node.name}"

    def declare(node: Node) -> None:
        for child in node.children or ():
            if child.children is not None:
                var_of[child.path] = var = f"m{len(var_of)}"
                body.append(f"{var} = {access(child)}")
                declare(child)

    declare(root)
    return access


class Lowering:
    """Lowers the codec types of one generated module."""

    def __init__(self, module: str, consts: Constants, module_of: dict[str, str]):
        self.module = module              # the generated module written: 'geometry_msgs.msg'
        self.consts = consts
        self.module_of = module_of        # codec type key -> its module

    def ref(self, kind: str, key: str, suffix: str) -> str:
        """How code in this module names another type's encoder/decoder."""
        fn = func_name(kind, key.split("__", 1)[1], suffix)
        other = self.module_of[key]
        return fn if other == self.module else f"{module_alias(other)}.{fn}"

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

    # --- decoder ------------------------------------------------------------------

    def decoder(self, ct: CodecType) -> Function:
        body: list[str] = []
        counter = [0]
        value_of: dict[str, str] = {}   # leaf path -> local variable or expression

        def fresh() -> str:
            counter[0] += 1
            return f"x{counter[0]}"

        def number_run(run: tuple[Node, ...]) -> None:
            names = [fresh() for _ in run]
            k = len(run)
            first = repr(run[0].path)
            body.append(f"if len(v) - i < {k}: raise _short({first})")
            if k == 1:
                body.append(f"{names[0]} = v[i]")
            else:
                body.append(f"{', '.join(names)} = v[i:i + {k}]")
            body.append(f"i += {k}")
            f32 = []
            for var, leaf in zip(names, run):
                enc: Number = leaf.encoding
                p = repr(leaf.path)
                if enc.is_float:
                    body.append(f"if type({var}) is not float: raise _bad_item({p}, 'a float', {var})")
                    if enc.prim == "float32":
                        f32.append((var, leaf.path))
                else:
                    lo, hi = enc.range
                    body.append(f"if type({var}) is not int or not {lo} <= {var} <= {hi}: "
                                f"raise _bad_item({p}, 'an {enc.prim}', {var})")
                value_of[leaf.path] = var
            for var, path in f32:
                body.append(f"if abs({var}) > {F32_MAX} and abs({var}) != _INF: "
                            f"raise _bad_item({path!r}, 'a float32', {var})")

        for leaf in segments(ct.root):
            if isinstance(leaf, NumberRun):
                number_run(leaf.leaves)
                continue
            enc = leaf.encoding
            if not_read(leaf, enc, body, value_of):
                continue
            var = fresh()
            lines = self._decode_leaf(leaf, enc, var, ct.profile_suffix)
            if isinstance(enc, NumberArray) and enc.tag is not None:
                lines = self._typed_or_items(leaf, enc, var, lines)
            body.extend(lines)
            value_of[leaf.path] = self._ros_value(enc, var)
        self.construct(ct.root, value_of, body, "i")
        return Function(func_name("dec", ct.name, ct.suffix), "v, i, C",
                        f"Read a {ct.full_name} ({ct.profile} profile) from items `v` at `i`; "
                        "return (message, next index).", body)

    @staticmethod
    def _typed_or_items(leaf: Node, enc: NumberArray, var: str, items: list[str]) -> list[str]:
        """A numeric array's decoder: one typed array item (section 4.1), else `items`."""
        p = repr(leaf.path)
        fixed = enc.array is ArrayKind.FIXED
        return [f"if i >= len(v): raise _short({p})",
                f"if type(v[i]) is _Tag:  # a typed array (tag {enc.tag})",
                f"    {var} = _typed_array(v[i], {enc.code!r}, {p}, {enc.size}, {fixed})",
                "    i += 1",
                "else:",
                *(f"    {line}" for line in items)]

    @staticmethod
    def _ros_value(enc, var: str) -> str:
        if isinstance(enc, ByteScalar):
            return f"bytes(({var},))"
        if isinstance(enc, Octets):
            return f"C.octet_list({var})" if enc.elem == "byte" else f"C.uint8_list({var})"
        return var

    def _decode_leaf(self, leaf: Node, enc, var: str, suffix: str) -> list[str]:
        p = repr(leaf.path)
        take = [f"if i >= len(v): raise _short({p})", f"{var} = v[i]", "i += 1"]
        if isinstance(enc, Filler):
            return take + [f"if type({var}) is not int or {var} != 0: raise _bad_item({p}, 'the unsigned 0 of an empty message', {var})"]
        if isinstance(enc, Bool):
            return take + [f"if {var} is not True and {var} is not False: {var} = _item_bool({var}, {p})"]
        if isinstance(enc, (TimeOfDay, TimeSinceEpoch, Quantized, Enumerated)) and \
                getattr(enc, "array", ArrayKind.NONE) is ArrayKind.NONE:
            top = index_max(enc)
            return take + [f"if type({var}) is not int or not 0 <= {var} <= {top}: "
                           f"raise _bad_item({p}, 'an index 0..{top}', {var})",
                           f"{var} = {self.index_value(enc, var, p)}"]
        if isinstance(enc, ByteScalar):
            return take + [f"if type({var}) is not int or not 0 <= {var} <= 255: raise _bad_item({p}, 'a byte', {var})"]
        if isinstance(enc, Text):
            lines = take + [f"if type({var}) is not str: raise _bad_item({p}, 'a text string', {var})"]
            if enc.bound is not None:
                lines.append(f"if len({var}) > {enc.bound}: raise _DecodeError({p}, f'{{len({var})}} characters, over the bound of {enc.bound}')")
            return lines
        if isinstance(enc, Octets):
            lines = take + [f"if type({var}) is not bytes: raise _bad_item({p}, 'a byte string', {var})"]
            if enc.array is ArrayKind.FIXED:
                lines.append(f"if len({var}) != {enc.size}: raise _DecodeError({p}, f'{{len({var})}} bytes in a fixed array of {enc.size}')")
            elif enc.array is ArrayKind.BOUNDED:
                lines.append(f"if len({var}) > {enc.size}: raise _DecodeError({p}, f'{{len({var})}} bytes, over the bound of {enc.size}')")
            return lines
        # Arrays of items: a count (or the fixed size), then the elements.
        counted = enc.array is not ArrayKind.FIXED or getattr(enc, "fixed_count", False)
        per_elem = max(enc.elem_min_items, 1) if isinstance(enc, MessageArray) else 1
        lines = []
        if counted:
            bound = enc.size if enc.array is not ArrayKind.UNBOUNDED else None
            lines.append(f"n = _count(v, i, {p}, {bound}, {per_elem})")
            if enc.array is ArrayKind.FIXED:
                lines.append(f"if n != {enc.size}: raise _DecodeError({p}, f'count {{n}} for a fixed array of {enc.size}')")
            lines.append("i += 1")
        else:
            lines.append(f"n = {enc.size}")
        if isinstance(enc, MessageArray):
            fn = self.ref("dec", enc.type_key, suffix)
            lines += [f"if (len(v) - i) < n * {per_elem}: raise _short({p})",
                      f"{var} = []",
                      "k = 0",
                      "try:",
                      "    for k in range(n):",
                      f"        e, i = {fn}(v, i, C)",
                      f"        {var}.append(e)",
                      "except _DecodeError as exc:",
                      f"    raise _under(exc, {p}, k) from None"]
            return lines
        lines += [f"if len(v) - i < n: raise _short({p})",
                  f"{var} = v[i:i + n]",
                  "i += n"]
        if isinstance(enc, NumberArray):
            if enc.elem_range is not None:
                lo, hi = enc.elem_range
                lines.append(f"if not _ints_in({var}, {lo}, {hi}): raise _bad_items({p}, {enc.prim!r}, {var})")
            else:
                lines.append(f"if not _only({var}, float): raise _bad_items({p}, {enc.prim!r}, {var})")
                if enc.prim == "float32" or enc.code == "f":
                    lines.append(f"if not _float32_ok({var}): raise _bad_items({p}, 'float32', {var})")
        elif isinstance(enc, BoolArray):
            lines.append(f"{var} = _item_bools({var}, {p})")
        elif isinstance(enc, (Quantized, Enumerated)):
            top = index_max(enc)
            lines.append(f"if not _ints_in({var}, 0, {top}): raise _bad_items({p}, 'index 0..{top}', {var})")
            lines.append(f"{var} = [{self.index_value(enc, 'n', p)} for n in {var}]")
        elif isinstance(enc, TextArray):
            lines.append(f"_check_texts({var}, {p}, {enc.text.bound})")
        return lines

    def index_value(self, enc, n: str, p: str) -> str:
        """The expression of the field value that index `n` stands for."""
        if isinstance(enc, Quantized):
            value = n if enc.b == 1 else f"{n} * {enc.b}"
            if enc.a:
                value = f"({enc.a} + {value})" if enc.a > 0 else f"({value} - {-enc.a})"
            if enc.d == 1:
                return value if not enc.is_float else f"float({value})"
            return f"{value} {'/' if enc.is_float else '//'} {enc.d}"
        if isinstance(enc, Enumerated):
            return f"{self.consts.values(enc.values)}[{n}]"
        if isinstance(enc, TimeOfDay):
            return f"_from_time_of_day({n}, {enc.step_ns}, C.{enc.class_key}, {p})"
        return f"_from_time_since({n}, {enc.epoch_ns}, {enc.step_ns}, C.{enc.class_key})"

    def construct(self, root: Node, value_of: dict[str, str], body: list[str], rest: str) -> None:
        """Append the statements that build the decoded message and `return (message, rest)`:
        rclpy's slots filled directly when `C` says its classes have the layout checked at
        first use (fill_slots), else the classes' constructors."""
        body.extend(fill_slots(root, value_of, rest))
        body.append(f"return {self._construct(root, value_of, body, 0, [0])}, {rest}")

    def _construct(self, node: Node, value_of: dict[str, str], body: list[str], depth: int,
                   temps: list[int]) -> str:
        """The expression that builds `node`; nested messages NEST_CHUNK levels down are
        built into locals (`t1 = ...` appended to `body`) first."""
        args = []
        for child in node.children:
            if child.children is not None:
                args.append(f"{child.name}={self._construct(child, value_of, body, depth + 1, temps)}")
            elif isinstance(child.encoding, (Absent, Filler)):
                continue
            elif isinstance(child.encoding, NumberArray) and child.encoding.tag is not None:
                args.append(f"{child.name}=C.numbers({value_of[child.path]})")   # a list or an array
            else:
                args.append(f"{child.name}={value_of[child.path]}")
        expr = f"C.{node.class_key}({', '.join(args)})"
        if depth and depth % NEST_CHUNK == 0:
            temps[0] += 1
            body.append(f"t{temps[0]} = {expr}")
            return f"t{temps[0]}"
        return expr


def fill_slots(root: Node, value_of: dict[str, str], rest: str) -> list[str]:
    """The fast way to build an rclpy message: a new instance of each class, every slot
    stored directly (`o._x = x1`), numeric arrays made the containers rclpy keeps
    (rosidl_layout.ros_store). Guarded by `C.fast_<key>`, which is true only for rclpy classes whose
    layout uwgen.runtime.wire.table.RosClasses verified, this one's and every inlined one's.
    None for a type with a leaf not on the wire (its default is the constructor's)."""
    if any(isinstance(leaf.encoding, Absent) for leaf in root.leaves()):
        return []
    lines = [f"if C.fast_{root.class_key}:  # rclpy's classes as checked at first use: fill their slots",
             "    cf = C.check_fields"]
    names = (f"o{k}" if k else "o" for k in itertools.count())

    def build(node: Node) -> str:
        var = next(names)
        lines.append(f"    {var} = _new(C.{node.class_key})")
        lines.append(f"    {var}._check_fields = cf")
        for child in node.children:
            if child.children is not None:
                lines.append(f"    {var}._{child.name} = {build(child)}")
            elif not isinstance(child.encoding, Filler):
                lines.append(f"    {var}._{child.name} = {ros_container(child.store, value_of[child.path])}")
        return var

    lines.append(f"    return {build(root)}, {rest}")
    return lines


def ros_container(store: str, expr: str) -> str:
    """`expr` (a decoded value) as rclpy keeps it in a slot of kind `store`."""
    kind, _, arg = store.partition(":")
    if kind == "ndarray":
        return f"C.ndarray({expr}, {arg!r})"
    if kind == "array":
        return f"C.array({expr}, {arg!r})"
    return expr


def index_max(enc) -> int:
    """The largest index an index-sent encoding (quantized, enum, time) may carry."""
    if isinstance(enc, Enumerated):
        return len(enc.values) - 1
    if isinstance(enc, TimeOfDay):
        return enc.count - 1
    return enc.nmax


def not_sent(leaf: Node, enc) -> str | None:
    """The comment an encoder writes for a leaf that is not on the wire (absent, or static:
    both sides know its value), else None: the leaf is sent."""
    if isinstance(enc, Absent):
        return f"# {leaf.path}: not sent ({enc.why})"
    if isinstance(enc, Static):
        return f"# {leaf.path}: not sent (static {enc.value!r})"
    return None


def not_read(leaf: Node, enc, body: list[str], value_of: dict[str, str]) -> bool:
    """For a decoder: whether `leaf` is not on the wire. An absent leaf gets a comment (the
    constructor leaves its default), a static one its value in `value_of`."""
    if isinstance(enc, Absent):
        body.append(f"# {leaf.path}: not on the wire ({enc.why})")
        return True
    if isinstance(enc, Static):
        value_of[leaf.path] = static_value(enc)
        return True
    return False


def static_value(enc: Static) -> str:
    """The expression a decoder fills a static field with (a fresh list each time)."""
    if enc.octets == "byte":
        return f"C.octet_list({bytes(enc.value)!r})"
    if enc.octets is not None:
        return f"C.uint8_list({bytes(enc.value)!r})"
    return repr(enc.value)


def quantize_lines(enc: Quantized, expr: str, p: str) -> list[str]:
    """Statements that set `n` to the index of `expr` on the grid of `enc`: the float
    estimate where it is provably the exact answer, else the exact integer computation."""
    exact = f"_quantize(x, {enc.a}, {enc.b}, {enc.d}, {enc.nmax}, {enc.clamp}, {p})"
    if enc.fast is None:
        return [f"x = {expr}", f"n = {exact}"]
    lo, inv, tol = enc.fast
    tol = 10.0 ** math.ceil(math.log10(tol))      # a round bound above the error bound
    scaled = offset(lo) if inv == 1.0 else f"{offset(lo)} * {inv!r}"
    return [f"x = {expr}",
            f"e = {scaled} if type(x) is float else -1.0",
            f"if 0.0 <= e <= {enc.nmax} and {tol!r} < (e + 0.5) % 1.0 < 1 - {tol!r}: n = int(e + 0.5)",
            f"else: n = {exact}  # outside the grid or near a rounding boundary: exact"]


def offset(lo: float) -> str:
    """`x - lo` as a reader would write it."""
    if lo == 0:
        return "x"
    return f"(x - {lo!r})" if lo > 0 else f"(x + {-lo!r})"
