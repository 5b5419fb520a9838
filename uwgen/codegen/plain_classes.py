"""The plain Python classes of a generated module: one per message type, with the
message's fields as `__init__` parameters (defaults as the definition gives them) and its
constants as class attributes; what decoders build when rclpy is not wanted.
"""
from __future__ import annotations

from uwgen.codegen.emit_common import module_alias
from uwgen.codegen.package_plan import ModulePlan, PlainClass, PlainField
from uwgen.idl.model import OCTET_TYPES, ArrayKind, Field, MessageDef


def plain_class(msg: MessageDef, mod: ModulePlan) -> PlainClass:
    fields = []
    for f in msg.fields:
        fields.append(_plain_field(f, msg.package, mod))
    constants = [(c.name, _literal(c.value, c.type)) for c in msg.constants]
    # Field names are __init__ parameters; none starts with '_' (see generator._python_safe).
    me = "_self" if any(f.name == "self" for f in msg.fields) else "self"
    return PlainClass(msg.name, msg.full_name, fields, constants, me)


def _class_ref(full_name: str, package: str, mod: ModulePlan) -> str:
    pkg, ns, name = full_name.split("/")
    other = f"{pkg}.{ns}"
    if other == mod.name:
        return name
    mod.need_import(other)
    return f"{module_alias(other)}.{name}"


def _literal(value, prim: str) -> str:
    if prim == "byte":
        return repr(bytes((value,))) if isinstance(value, int) else repr(value)
    if prim in ("float32", "float64"):
        return repr(float(value))
    return repr(value)


_ZERO = {"bool": "False", "string": "''", "wstring": "''", "float32": "0.0", "float64": "0.0", "byte": "b'\\x00'"}


def _plain_field(f: Field, package: str, mod: ModulePlan) -> PlainField:
    t = f.type
    if not t.is_primitive:
        cls = _class_ref(t.base, package, mod)
        if t.array is ArrayKind.FIXED:
            # No builtin here: a field (an __init__ parameter) may be named `range`.
            return PlainField(f.name, "None", f"[{cls}() for _ in [None] * {t.size}] if {f.name} is None else {f.name}")
        if t.is_array:
            return PlainField(f.name, "None", f"[] if {f.name} is None else {f.name}")
        return PlainField(f.name, "None", f"{cls}() if {f.name} is None else {f.name}")
    if not t.is_array:
        value = _ZERO.get(t.base, "0") if f.default is None else _literal(f.default, t.base)
        return PlainField(f.name, value, f.name)
    octet = t.base in OCTET_TYPES
    if octet:
        if f.default is not None:
            data = bytes(f.default if t.base != "byte" else [v if isinstance(v, int) else v[0] for v in f.default])
            return PlainField(f.name, repr(data), f.name)
        return PlainField(f.name, repr(bytes(t.size)) if t.array is ArrayKind.FIXED else "b''", f.name)
    if f.default is not None:
        items = ", ".join(_literal(v, t.base) for v in f.default)
        return PlainField(f.name, "None", f"[{items}] if {f.name} is None else {f.name}")
    if t.array is ArrayKind.FIXED:
        return PlainField(f.name, "None", f"[{_ZERO.get(t.base, '0')}] * {t.size} if {f.name} is None else {f.name}")
    return PlainField(f.name, "None", f"[] if {f.name} is None else {f.name}")
