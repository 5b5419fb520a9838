"""Turn rosidl_adapter's parse results and uwgen's into the same comparable shape."""
from __future__ import annotations

from uwgen.idl.model import ArrayKind, MessageDef


def ref_type(t) -> tuple:
    """rosidl_adapter's Type as (base, array kind, size, string bound) in uwgen's terms."""
    base = f"{t.pkg_name}/msg/{t.type}" if t.pkg_name else t.type
    if not t.is_array:
        kind, size = ArrayKind.NONE, None
    elif t.array_size is None:
        kind, size = ArrayKind.UNBOUNDED, None
    elif t.is_upper_bound:
        kind, size = ArrayKind.BOUNDED, t.array_size
    else:
        kind, size = ArrayKind.FIXED, t.array_size
    return base, kind, size, t.string_upper_bound


def ref_shape(spec) -> dict:
    return {
        "fields": [(f.name, ref_type(f.type), f.default_value) for f in spec.fields],
        "constants": [(c.name, c.type, c.value) for c in spec.constants],
    }


def _plain(value):
    return list(value) if isinstance(value, tuple) else value


def our_shape(message: MessageDef) -> dict:
    return {
        "fields": [
            (f.name, (f.type.base, f.type.array, f.type.size, f.type.string_bound), _plain(f.default))
            for f in message.fields
        ],
        "constants": [(c.name, c.type, c.value) for c in message.constants],
    }
