"""Names in ROS 2 interface definitions: what is valid and how type names are spelled.

The patterns are those `rosidl_adapter` enforces when it turns a `.msg` into IDL, so a
file uwgen accepts is also one ROS can build. Kept apart from the parser because the
manifest loader and the interface library validate and normalise the same names.
"""
from __future__ import annotations

import re

# Lower case, starts with a letter, no "__", no trailing "_" (package and field names).
PACKAGE_NAME = re.compile(r"(?!.*__)(?!.*_$)[a-z][a-z0-9_]*")
FIELD_NAME = PACKAGE_NAME
# CamelCase type names.
MESSAGE_NAME = re.compile(r"[A-Z][A-Za-z0-9]*")
# UPPER_CASE constants, no "__", no leading or trailing "_". Every character has exactly one
# way to match (an "_" only before a letter or digit), so matching is linear in the length;
# rosidl's own spelling of it, `[A-Z]([A-Z0-9_]?[A-Z0-9]+)*`, backtracks exponentially on a
# name that fails late (`POWER_SUPPLY_TECHNOLOGY_UNKNOWNxx`: 34 s).
CONSTANT_NAME = re.compile(r"[A-Z](?:_?[A-Z0-9])*")

# Suffixes rosidl accepts after a message name (the parts of services and actions).
_MESSAGE_SUFFIXES = ("_Request", "_Response", "_Goal", "_Result", "_Feedback")
NAMESPACES = ("msg", "srv", "action")


def is_package_name(name: str) -> bool:
    return PACKAGE_NAME.fullmatch(name) is not None


def is_field_name(name: str) -> bool:
    return FIELD_NAME.fullmatch(name) is not None


def is_constant_name(name: str) -> bool:
    return CONSTANT_NAME.fullmatch(name) is not None


def is_message_name(name: str) -> bool:
    """CamelCase, optionally with a service/action part suffix (as rosidl_adapter allows)."""
    if name.startswith("Sample_"):
        name = name[len("Sample_"):]
    for suffix in _MESSAGE_SUFFIXES:
        if name.endswith(suffix):
            name = name[: -len(suffix)]
    return MESSAGE_NAME.fullmatch(name) is not None


def split_type_name(name: str) -> tuple[str, str | None, str] | None:
    """Split `pkg/Name` or `pkg/ns/Name` into (pkg, ns or None, Name); None if malformed."""
    parts = name.split("/")
    if len(parts) == 2:
        pkg, type_name = parts
        ns = None
    elif len(parts) == 3:
        pkg, ns, type_name = parts
    else:
        return None
    if not is_package_name(pkg) or not is_message_name(type_name):
        return None
    if ns is not None and ns not in NAMESPACES:
        return None
    return pkg, ns, type_name
