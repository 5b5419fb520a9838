"""ROS 2 message definitions in the `ros2msg` text MCAP schemas carry (what rosbag2 writes):
the type's own fields, then each type it uses once, after a line of `=` and `MSG: pkg/Type`.

Built from the rclpy class's own field table (`get_fields_and_field_types`), so any type
rclpy can import has a schema, with no .msg file to find. Constants and default values are
left out: readers need only the fields to decode.
"""
from __future__ import annotations

import importlib
import re
from typing import Any

# rosidl's IDL names of primitive types -> their .msg spelling
PRIMITIVES = {"boolean": "bool", "octet": "byte", "char": "char", "float": "float32",
              "double": "float64", "long double": "float64", "int8": "int8", "uint8": "uint8",
              "int16": "int16", "uint16": "uint16", "int32": "int32", "uint32": "uint32",
              "int64": "int64", "uint64": "uint64", "string": "string", "wstring": "wstring"}
SEPARATOR = "=" * 80

_SEQUENCE = re.compile(r"^sequence<(.+?)(?:,\s*(\d+))?>$")
_ARRAY = re.compile(r"^(.+)\[(\d+)\]$")


def ros_type_name(cls: type) -> str:
    """`pkg/msg/Type` of an rclpy message class."""
    pkg = cls.__module__.split(".")[0]
    return f"{pkg}/msg/{cls.__name__}"


def message_class(name: str) -> type:
    """The rclpy class of `pkg/Type` or `pkg/msg/Type`."""
    parts = name.split("/")
    pkg, typ = parts[0], parts[-1]
    return getattr(importlib.import_module(f"{pkg}.msg"), typ)


def _field_type(idl: str) -> tuple[str, str | None]:
    """(.msg spelling, nested type name or None) of one rosidl field type."""
    m = _SEQUENCE.match(idl)
    if m:
        inner, nested = _field_type(m.group(1))
        return (f"{inner}[<={m.group(2)}]" if m.group(2) else f"{inner}[]"), nested
    m = _ARRAY.match(idl)
    if m:
        inner, nested = _field_type(m.group(1))
        return f"{inner}[{m.group(2)}]", nested
    base, bound = idl, ""
    if "<=" in idl:                                   # string<=10
        base, bound = idl.split("<=", 1)
        bound = f"<={bound}"
    if base in PRIMITIVES:
        return PRIMITIVES[base] + bound, None
    return idl, idl                                    # pkg/Type: a nested message


def _fields(cls: type) -> tuple[list[str], list[str]]:
    lines, nested = [], []
    for name, idl in cls.get_fields_and_field_types().items():
        spelled, inner = _field_type(idl)
        lines.append(f"{spelled} {name}")
        if inner is not None:
            nested.append(inner)
    return lines, nested


def definition(cls: Any) -> str:
    """The ros2msg schema text of `cls` and every type it uses."""
    lines, todo = _fields(cls)
    seen: set[str] = set()
    out = ["\n".join(lines)]
    while todo:
        name = todo.pop(0)
        if name in seen:
            continue
        seen.add(name)
        inner_lines, inner = _fields(message_class(name))
        out.append(f"{SEPARATOR}\nMSG: {name}\n" + "\n".join(inner_lines))
        todo += inner
    return "\n".join(out) + "\n"
