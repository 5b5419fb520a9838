"""How rclpy holds a message (rosidl_generator_py's layout).

Decoders that build rclpy messages fill their slots (`_x`) directly instead of calling
the constructor and property setters, which is most of rclpy's cost. They may only when
rclpy's class is laid out as assumed here; uwgen.runtime.wire.table.RosClasses checks each
class against its `ros_layout` the first time it is used and falls back to the
constructor when anything differs.
"""
from __future__ import annotations

from uwgen.codegen.encodings import STRUCT_CODES, type_key
from uwgen.idl.model import ArrayKind, FieldType, MessageDef

ROSIDL_NAMES = {"bool": "boolean", "byte": "octet", "char": "uint8", "float32": "float", "float64": "double"}
NUMPY_DTYPES = {"char": "uint8", "float32": "float32", "float64": "float64", "int8": "int8", "uint8": "uint8",
                "int16": "int16", "uint16": "uint16", "int32": "int32", "uint32": "uint32", "int64": "int64",
                "uint64": "uint64"}
SCALAR_STORES = {"bool": "bool", "byte": "bytes", "string": "str", "wstring": "str"}


def rosidl_type(ftype: FieldType) -> str:
    """The field's type as rclpy's `_fields_and_field_types` spells it: 'double',
    'sequence<float>', 'double[36]', 'string<22>', 'sequence<geometry_msgs/Point32, 3>'."""
    base = ftype.base
    if not ftype.is_primitive:
        pkg, _ns, name = base.split("/")
        base = f"{pkg}/{name}"
    else:
        base = ROSIDL_NAMES.get(base, base)
        if ftype.string_bound is not None:
            base += f"<{ftype.string_bound}>"
    if ftype.array is ArrayKind.FIXED:
        return f"{base}[{ftype.size}]"
    if ftype.array is ArrayKind.BOUNDED:
        return f"sequence<{base}, {ftype.size}>"
    if ftype.array is ArrayKind.UNBOUNDED:
        return f"sequence<{base}>"
    return base


def ros_store(ftype: FieldType) -> str:
    """What rclpy keeps in the field's slot: 'float', 'int', 'bool', 'bytes', 'str',
    'msg:<key>' (a nested message), 'list', 'ndarray:<dtype>' (fixed numeric arrays,
    numpy) or 'array:<code>' (numeric sequences, array.array)."""
    if not ftype.is_primitive:
        return "list" if ftype.is_array else f"msg:{type_key(ftype.base)}"
    if not ftype.is_array:
        if ftype.base in SCALAR_STORES:
            return SCALAR_STORES[ftype.base]
        return "float" if ftype.base.startswith("float") else "int"
    if ftype.base not in NUMPY_DTYPES:
        return "list"          # bool, byte (1-byte bytes), string and wstring elements
    if ftype.array is ArrayKind.FIXED:
        return f"ndarray:{NUMPY_DTYPES[ftype.base]}"
    return f"array:{STRUCT_CODES[ftype.base]}"


def ros_layout(msg: MessageDef) -> tuple[tuple[str, str, str], ...]:
    """(field name, rosidl type, store) of every field, in order: what rclpy's class of
    `msg` must look like for decoders to fill its slots."""
    return tuple((f.name, rosidl_type(f.type), ros_store(f.type)) for f in msg.fields)
