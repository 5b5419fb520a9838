"""Fully qualified ROS 2 names, checked as rcl checks them (topics, services, namespaces)."""
from __future__ import annotations

import re

ROS_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def validate_ros_name(name: str) -> str | None:
    """Why `name` is not a fully qualified ROS 2 topic/service name, or None if it is one.

    The rules of rcl/rmw's full-name validation: leads with '/', tokens of letters, digits
    and '_' that do not start with a digit, no '//', no trailing '/'. Relative names are
    refused because a bridge node's namespace would silently change them.
    """
    if not name:
        return "a ROS name must not be empty"
    if not name.startswith("/"):
        return f"'{name}' is not a fully qualified ROS name: it must start with '/'"
    if name == "/":
        return "'/' alone is not a topic or service name"
    if name.endswith("/"):
        return f"'{name}' must not end with '/'"
    if "//" in name:
        return f"'{name}' must not contain '//'"
    for token in name[1:].split("/"):
        if token[0].isdigit():
            return f"'{name}': the part '{token}' must not start with a digit"
        if not ROS_TOKEN.fullmatch(token):   # the pattern is ASCII-only
            return f"'{name}' may contain only letters, digits, '_' and '/'"
    if len(name) > 255:
        return f"'{name[:20]}...' is longer than 255 characters"
    return None
