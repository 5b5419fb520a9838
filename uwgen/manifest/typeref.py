"""Type names in the manifest (`type: pkg/msg/Name`) resolved against the interface library."""
from __future__ import annotations

import difflib

import yaml

from uwgen.idl import names as idl_names
from uwgen.idl.loader import InterfaceLibrary
from uwgen.idl.model import MessageDef, ServiceDef
from uwgen.manifest.nodes import Reader


def resolve_type(r: Reader, lib: InterfaceLibrary, type_node: yaml.Node, type_text: str, want: str,
                 label: str):
    """(full name, MessageDef) for want='msg' or (full name, ServiceDef) for want='srv' named by
    `type_text`; a located error saying what is wrong (and what was meant) otherwise."""
    split = idl_names.split_type_name(type_text)
    if split is None:
        raise r.error(type_node, f"type '{type_text}' of {label} is not a type name: expected pkg/{want}/Name or pkg/Name")
    pkg, ns, name = split
    other = "srv" if want == "msg" else "msg"
    full = f"{pkg}/{want}/{name}"
    known = full in lib
    if (ns == other or (ns is None and not known)) and f"{pkg}/{other}/{name}" in lib:
        if want == "msg":
            raise r.error(type_node, f"type '{type_text}' is a service, but {label} needs a message type (pkg/msg/Name); declare it under services:")
        raise r.error(type_node, f"type '{type_text}' is a message, but {label} needs a service type (pkg/srv/Name); declare it under topics:")
    if ns == other:
        raise r.error(type_node, f"{label} needs a {'message' if want == 'msg' else 'service'} type pkg/{want}/Name, got '{type_text}'")
    if not known:
        raise r.error(type_node, f"unknown type '{type_text}' for {label}: {full} not found"
                                 f"{did_you_mean(lib, full)} (looked in: {lib.looked_in()})")
    definition = lib.get(full)
    expected = MessageDef if want == "msg" else ServiceDef
    if not isinstance(definition, expected):  # a service's part, e.g. pkg/srv/Name_Request as a service
        raise r.error(type_node, f"type '{type_text}' of {label} is not a {want}")
    return full, definition


def did_you_mean(lib: InterfaceLibrary, full: str) -> str:
    """'; did you mean pkg/kind/Name?' for an unknown type: the same name in another
    package, else the closest spelling of its kind; '' when nothing is close."""
    pkg, kind, name = full.split("/")
    names = [n for n in lib.all_names() if n.split("/")[1] == kind]
    same = [n for n in names if n.split("/")[2].lower() == name.lower() and n != full]
    close = same or difflib.get_close_matches(full, names, n=1, cutoff=0.8)
    if not close:
        return ""
    return f"; did you mean {' or '.join(close[:2])}?"
