"""The codec IR: how each message type is laid out on the wire under one profile.

Built once from uwgen.idl.model definitions, it is the single representation between
parsing and emitting (like pymavlink's mavparse). Every decision about the wire is
made here, at generation time: which fields are flattened in place, which numbers are
packed together, how each array travels, what a profile changes. The emitter only
lowers these nodes to Python statements and the templates only lay them out.

A codec tree mirrors the message: a `Node` per field; nested messages that are not in
arrays are inlined (their fields are flattened in place on the wire); arrays of
messages refer to the element type's own codec by name.

The leaf encodings are in uwgen.codegen.encodings; how rclpy lays out a message (for
decoders that fill its slots) is in uwgen.codegen.rosidl_layout.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

from uwgen.codegen.encodings import (
    STRUCT_CODES, Absent, Bool, BoolArray, ByteScalar, ColumnArray, Encoding, Enumerated, Filler, MessageArray,
    Number, NumberArray, Octets, Quantized, Static, Text, TextArray, TimeOfDay, TimeSinceEpoch,
    field_encoding, type_key,
)
from uwgen.codegen.rosidl_layout import ros_store
from uwgen.codegen.shape import MAX_NESTING, NestingCheck
from uwgen.idl.model import INTEGER_RANGES, OCTET_TYPES, ArrayKind, FieldType, MessageDef
from uwgen.manifest.model import MAX_COUNT, MAX_LENGTH, NATIVE, PACKED, RMW_DESERT, FieldEncoding
from uwgen.runtime.wire.codec import RMW_MAX_ITEMS, RMW_MAX_TEXT_BYTES, head_size
from uwgen.runtime.wire.typed_arrays import TYPED_TAGS
from uwgen.runtime.wire.framing import MAX_PAYLOAD


class ProfileError(Exception):
    """A type that a profile can certainly not carry (refused at build time)."""


@dataclass
class Node:
    """One field of a codec tree. Exactly one of `encoding` and `children` is set."""
    name: str                         # attribute name ('' for a Filler)
    path: str                         # dotted path from the type's root: 'pose.position.x'
    encoding: Encoding | None = None
    children: list["Node"] | None = None
    class_key: str | None = None      # for inlined nested messages: the CodecType.key
    # How rclpy's class holds this field (ros_store): what a decoder that fills rclpy's
    # slots directly stores. From the field's ROS type, whatever the manifest sends.
    store: str = field(default="", metadata={"schema": False})

    def leaves(self) -> Iterator["Node"]:
        if self.children is None:
            yield self
        else:
            for child in self.children:
                yield from child.leaves()


@dataclass
class CodecType:
    """The codec of one message type under one profile."""
    key: str                    # 'geometry_msgs__Twist' (unique Python-safe name)
    full_name: str              # 'geometry_msgs/msg/Twist'
    package: str
    namespace: str              # 'msg', or 'srv' for a service's request/response
    name: str                   # 'Twist', 'SetBool_Request'
    profile: str
    root: Node                  # children: the fields (or one Filler)
    min_items: int              # fewest CBOR items a value of this type takes
    fixed_items: int | None     # item count when the type has no variable part
    min_bytes: int              # fewest payload bytes (header excluded)
    uses: list[str] = field(default_factory=list)   # keys of types referenced by arrays
    # '' or the name of a manifest entry's own codec with field encodings: 't4' (topic 4),
    # 'q21'/'r21'. It names functions only, so the schema fingerprint leaves it out.
    variant: str = field(default="", metadata={"schema": False})

    @property
    def module(self) -> str:
        """The generated module that holds it: 'geometry_msgs.msg'."""
        return f"{self.package}.{self.namespace}"

    @property
    def profile_suffix(self) -> str:
        """What names the profile in function names (types used by arrays share it)."""
        return PROFILE_SUFFIX[self.profile]

    @property
    def suffix(self) -> str:
        return self.profile_suffix + (f"_{self.variant}" if self.variant else "")


PROFILE_SUFFIX = {NATIVE: "", RMW_DESERT: "_rmw", PACKED: "_pk"}


@dataclass(frozen=True)
class NumberRun:
    """Consecutive Number leaves: encoded through one struct, decoded with one slice."""
    leaves: tuple[Node, ...]


def segments(root: Node) -> list[NumberRun | Node]:
    """The leaves of a codec tree in wire order, consecutive numbers grouped into runs."""
    out: list[NumberRun | Node] = []
    run: list[Node] = []
    for leaf in root.leaves():
        if isinstance(leaf.encoding, Number):
            run.append(leaf)
            continue
        if run:
            out.append(NumberRun(tuple(run)))
            run = []
        out.append(leaf)
    if run:
        out.append(NumberRun(tuple(run)))
    return out


def variant_name(letter: str, ident: int, fields: tuple) -> str:
    """The name of a manifest entry's own codec when it has field encodings: 't4' for
    topic 4, 'q21' / 'r21' for the request / response of service 21; '' without."""
    return f"{letter}{ident}" if fields else ""



# --- building ------------------------------------------------------------------------

class IRBuilder:
    """Builds CodecTypes for message definitions, resolving nested types by name."""

    def __init__(self, lookup, max_nesting: int = MAX_NESTING):
        """`lookup(full_name) -> MessageDef` resolves nested message types."""
        self._lookup = lookup
        self._cache: dict[tuple[str, str, str], CodecType] = {}
        self._nesting = NestingCheck(lookup, max_nesting)   # recursive / too deep types: DefinitionError

    def codec(self, msg: MessageDef, profile: str, fields: tuple[FieldEncoding, ...] = (),
              variant: str = "") -> CodecType:
        """The codec of `msg`; with manifest `fields`, a variant named `variant`."""
        key = (msg.full_name, profile, variant)
        hit = self._cache.get(key)
        if hit is None:
            self._nesting.check(msg)
            hit = self._cache[key] = self._build(msg, profile, {f.path: f for f in fields}, variant)
        return hit

    def by_key(self, key: str, profile: str) -> CodecType:
        """The plain codec (no field encodings) already built for type `key` in `profile`."""
        for (_name, prof, variant), ct in self._cache.items():
            if ct.key == key and prof == profile and not variant:
                return ct
        raise KeyError((key, profile))

    def codecs_for(self, msg: MessageDef, profile: str) -> list[CodecType]:
        """This type's codec and those of every type it uses, dependencies first."""
        out: dict[str, CodecType] = {}

        def visit(m: MessageDef) -> None:
            ct = self.codec(m, profile)
            if ct.key in out:
                return
            for f in m.fields:
                if not f.type.is_primitive:
                    visit(self._lookup(f.type.base))
            out[ct.key] = ct

        visit(msg)
        return list(out.values())

    # ---

    def _build(self, msg: MessageDef, profile: str, fields: dict[str, FieldEncoding], variant: str) -> CodecType:
        uses: list[str] = []
        outer, self._encodings = self._encodings, fields   # element types of arrays have none
        try:
            root = Node(name="", path="", children=self._fields(msg, profile, "", uses),
                        class_key=type_key(msg.full_name))
        finally:
            self._encodings = outer
        size = self._size(root)
        return CodecType(
            key=type_key(msg.full_name), full_name=msg.full_name, package=msg.package,
            namespace=msg.namespace, name=msg.name, profile=profile, root=root, min_items=size.items,
            fixed_items=size.fixed, min_bytes=size.bytes, uses=uses, variant=variant)

    _encodings: dict[str, FieldEncoding] = {}

    def _fields(self, msg: MessageDef, profile: str, prefix: str, uses: list[str]) -> list[Node]:
        if not msg.fields:
            return [Node(name="", path=prefix or "(empty)", encoding=Filler())]
        nodes = []
        for f in msg.fields:
            path = f"{prefix}.{f.name}" if prefix else f.name
            nodes.append(self._field(f.name, f.type, profile, path, uses))
        return nodes

    def _field(self, name: str, ftype: FieldType, profile: str, path: str, uses: list[str]) -> Node:
        node = self._field_node(name, ftype, profile, path, uses)
        node.store = ros_store(ftype)
        return node

    def _field_node(self, name: str, ftype: FieldType, profile: str, path: str, uses: list[str]) -> Node:
        rmw = profile == RMW_DESERT
        fe = self._encodings.get(path)
        if fe is not None and fe.kind not in (MAX_COUNT, MAX_LENGTH):
            return Node(name, path, field_encoding(fe, ftype))
        if fe is not None and fe.kind == MAX_COUNT:
            ftype = FieldType(ftype.base, ArrayKind.BOUNDED, fe.bound, ftype.string_bound)
        elem = self._encodings.get(path + "[]") if ftype.is_array else None
        if fe is not None and fe.kind == MAX_LENGTH or elem is not None and elem.kind == MAX_LENGTH:
            ftype = FieldType(ftype.base, ftype.array, ftype.size, (fe or elem).bound)
        elif elem is not None:
            return Node(name, path, field_encoding(elem, ftype.element(), ftype.array, ftype.size))
        if not ftype.is_primitive:
            sub = self._lookup(ftype.base)
            if ftype.is_array:
                elem = self.codec(sub, profile)
                if elem.key not in uses:
                    uses.append(elem.key)
                columns = self._columns(elem) if profile == NATIVE else None
                if columns:
                    return Node(name, path, ColumnArray(ftype.array, ftype.size, elem.key, elem.min_items,
                                                        elem.fixed_items, elem.min_bytes, columns=columns))
                return Node(name, path, MessageArray(ftype.array, ftype.size, elem.key,
                                                     elem.min_items, elem.fixed_items, elem.min_bytes))
            return Node(name, path, children=self._fields(sub, profile, path, uses),
                        class_key=type_key(sub.full_name))
        base = ftype.base
        if base == "byte" and rmw:
            return Node(name, path, Absent("rmw_desert neither sends nor expects byte fields"))
        if not ftype.is_array:
            return Node(name, path, self._scalar(base, ftype.string_bound, rmw))
        if base in OCTET_TYPES and not rmw:
            return Node(name, path, Octets(ftype.array, ftype.size, base))
        if base == "bool":
            return Node(name, path, BoolArray(ftype.array, ftype.size, cbor_bool=rmw))
        if base in ("string", "wstring"):
            text = self._scalar(base, ftype.string_bound, rmw)
            return Node(name, path, TextArray(ftype.array, ftype.size, text,
                                              fixed_count=rmw and ftype.array is ArrayKind.FIXED))
        code = "f" if rmw and base == "float64" else STRUCT_CODES[base]
        tag = TYPED_TAGS.get(code) if profile == NATIVE else None
        return Node(name, path, NumberArray(base, code, ftype.array, ftype.size,
                                            INTEGER_RANGES.get(base), tag))

    @staticmethod
    def _columns(elem: CodecType) -> tuple[tuple[str, str], ...] | None:
        """The columns of an array of `elem` (wire format section 4.2): (path, struct code)
        of each of its numbers, when every field of `elem` is one (nested messages
        flattened); else None: the array travels as items."""
        leaves = list(elem.root.leaves())
        if not all(isinstance(leaf.encoding, Number) for leaf in leaves):
            return None
        return tuple((leaf.path, leaf.encoding.code) for leaf in leaves)

    @staticmethod
    def _scalar(base: str, bound: int | None, rmw: bool) -> Encoding:
        if base == "bool":
            return Bool(cbor_bool=rmw)
        if base == "byte":
            return ByteScalar()
        if base in ("string", "wstring"):
            return Text(wide=base == "wstring", bound=bound,
                        max_bytes=RMW_MAX_TEXT_BYTES if rmw else None)
        code = "f" if rmw and base == "float64" else STRUCT_CODES[base]
        return Number(base, code)

    # --- sizes: the fewest items and bytes a value can take, for profile limits ---

    def _size(self, node: Node) -> "_Size":
        """The fewest items and bytes a value of this node takes (header excluded)."""
        if node.children is not None:
            return sum((self._size(c) for c in node.children), _Size(0, 0, 0))
        enc = node.encoding
        fixed_array = getattr(enc, "array", None) is ArrayKind.FIXED
        if isinstance(enc, (Absent, Static)):
            return _Size(0, 0, 0)
        if isinstance(enc, (TimeOfDay, TimeSinceEpoch)) or getattr(enc, "array", None) is ArrayKind.NONE:
            return _Size(1, 1, 1)
        if isinstance(enc, (Quantized, Enumerated)):
            if not fixed_array:
                return _Size(1, None, 1)
            return _Size(enc.size, enc.size, enc.size)
        if isinstance(enc, Number):
            return _Size(1, 1, 3 if enc.is_float else 1)
        if isinstance(enc, (Bool, ByteScalar, Text, Filler)):
            return _Size(1, 1, 1)
        if isinstance(enc, ColumnArray) and fixed_array:   # one byte string or the items per column
            n = enc.size
            per = [n if code not in "fd" else min(3 * n, head_size(2 * n) + 2 * n) for _p, code in enc.columns]
            return _Size(len(enc.columns) if n else 0, None, sum(per))
        if not fixed_array:                     # a count, then maybe nothing
            return _Size(1, None, 1)
        if isinstance(enc, Octets):
            return _Size(1, 1, 1 + enc.size)
        if isinstance(enc, NumberArray) and enc.tag is not None:   # items, or one typed array
            typed = 2 + head_size(enc.size * enc.width) + enc.size * enc.width
            per = 3 if enc.prim.startswith("float") else 1
            return _Size(1, None, min(enc.size * per, typed))
        if isinstance(enc, (NumberArray, BoolArray, TextArray)):
            count = 1 if getattr(enc, "fixed_count", False) else 0
            per = 3 if isinstance(enc, NumberArray) and enc.prim.startswith("float") else 1
            return _Size(enc.size + count, enc.size + count, enc.size * per + count)
        if isinstance(enc, MessageArray):
            fixed = None if enc.elem_fixed_items is None else enc.size * enc.elem_fixed_items
            return _Size(enc.size * enc.elem_min_items, fixed, enc.size * enc.elem_min_bytes)
        raise AssertionError(enc)


@dataclass(frozen=True)
class _Size:
    items: int              # fewest CBOR items
    fixed: int | None       # the exact item count, when no part of the type varies
    bytes: int              # fewest payload bytes

    def __add__(self, other: "_Size") -> "_Size":
        fixed = None if self.fixed is None or other.fixed is None else self.fixed + other.fixed
        return _Size(self.items + other.items, fixed, self.bytes + other.bytes)


def check_profile_limits(ct: CodecType, header_items: int) -> None:
    """Refuse, at build time, a type that an rmw_desert receiver can never take."""
    if ct.profile != RMW_DESERT:
        return
    items = ct.min_items + header_items
    if items > RMW_MAX_ITEMS:
        raise ProfileError(
            f"{ct.full_name}: every message takes at least {items} CBOR items, and an rmw_desert "
            f"receiver keeps only {RMW_MAX_ITEMS}")
    size = ct.min_bytes + header_items
    if size > MAX_PAYLOAD:
        raise ProfileError(
            f"{ct.full_name}: every message takes at least {size} bytes, over the {MAX_PAYLOAD}-byte "
            "payload an rmw_desert receiver can take (no fragmentation in this profile)")

