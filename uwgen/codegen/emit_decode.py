"""Lower codec IR to decoders: `dec[_rmw]_<Name>(v, i, C)` reads items from list `v` at
index `i` and returns `(message, next_i)`, building classes from namespace `C` (rclpy classes,
their slots filled directly where their layout was checked, or the generated plain ones).
Every item's type and range is checked in straight-line code; errors name the field path.
The encoders are in uwgen.codegen.emit, whose `Lowering` extends `Decoding`.
"""
from __future__ import annotations

import itertools

from uwgen.codegen.emit_common import (
    F32_MAX, Constants, Function, func_name, index_max, module_alias, not_read,
)
from uwgen.codegen.encodings import (
    Absent, Bool, BoolArray, ByteScalar, ColumnArray, Enumerated, Filler, MessageArray, Number, NumberArray, Octets,
    Quantized, Text, TextArray, TimeOfDay, TimeSinceEpoch,
)
from uwgen.codegen.ir import CodecType, Node, NumberRun, segments
from uwgen.idl.model import ArrayKind

# A decoder builds its message in one expression, `C.A(b=C.B(c=...))`, one pair of
# parentheses per nesting level; Python's parser refuses more than 200 nested ones
# ("too many nested parentheses"). Every NEST_CHUNK levels the inner message is built
# into a local first, so no expression nests deeper, whatever the type's depth.
NEST_CHUNK = 32


class Decoding:
    """The decoder half of the lowering of one generated module's codec types."""

    def __init__(self, module: str, consts: Constants, module_of: dict[str, str]):
        self.module = module              # the generated module written: 'geometry_msgs.msg'
        self.consts = consts
        self.module_of = module_of        # codec type key -> its module

    def ref(self, kind: str, key: str, suffix: str) -> str:
        """How code in this module names another type's encoder/decoder."""
        fn = func_name(kind, key.split("__", 1)[1], suffix)
        other = self.module_of[key]
        return fn if other == self.module else f"{module_alias(other)}.{fn}"

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
        if isinstance(enc, ColumnArray):
            return self._columns(enc, var, p, suffix)
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

    def _columns(self, enc: ColumnArray, var: str, p: str, suffix: str) -> list[str]:
        """An array by columns (section 4.2): the count (sequences), the columns read
        row-major, then each element through its type's decoder, which checks its values."""
        if enc.array is ArrayKind.FIXED:
            lines = [f"n = {enc.size}"]
        else:
            bound = enc.size if enc.array is ArrayKind.BOUNDED else None
            lines = [f"n = _count(v, i, {p}, {bound}, 0)  # columns may be one byte string each", "i += 1"]
        fn = self.ref("dec", enc.type_key, suffix)
        return lines + [f"r, i = _decode_columns(v, i, n, {enc.columns!r}, {p})",
                        f"{var} = []",
                        "j = k = 0",
                        "try:",
                        "    for k in range(n):",
                        f"        e, j = {fn}(r, j, C)",
                        f"        {var}.append(e)",
                        "except _DecodeError as exc:",
                        f"    raise _under(exc, {p}, k) from None"]

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
