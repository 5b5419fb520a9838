"""The two namespaces generated decoders build messages from (`C.pkg__Name`).

`PlainClasses` holds the generated plain classes. `RosClasses` imports rclpy's classes on
first use and, for each, decides once whether decoders may build its messages the fast
way: a bare instance (`object.__new__`) whose slots (`_x`) they fill directly, instead of
the constructor, which runs a property setter per field and builds a default for every
nested message even when one is passed (most of what decoding into rclpy costs).

That is only correct while rosidl_generator_py lays classes out as uwgen assumes, so
`RosClasses` checks every class against the layout the generator recorded for it
(uwgen.codegen.rosidl_layout.ros_layout) before saying yes (`C.fast_<key>`): the same slots, the
same field types, getters that read the slots, and a default instance holding in each
slot the container the fast path stores (numpy arrays for fixed numeric arrays,
array.array for numeric sequences, lists, ...). Anything else, and the decoders of that
type keep using the constructor, as they always may.

Encoders use the same answer: for a message of a class with `C.fast_<key>`,
uwgen.runtime.wire.table.TypeCodec.encode calls the encoder that reads the slots (`m._x`)
rather than the properties (a Python call each).
"""
from __future__ import annotations

import array
import importlib
import logging
import os

log = logging.getLogger("uwgen.codec")

new_message = object.__new__   # what a fast decoder creates a message with (no __init__)


class PlainClasses:
    """Namespace of the generated plain classes, as decoders name them (`C.pkg__Name`)."""

    check_fields = False

    def __init__(self, classes: dict[str, type]):
        self.__dict__.update(classes)

    def __getattr__(self, name: str):
        if name.startswith("fast_"):
            setattr(self, name, False)   # plain classes are built by their constructors
            return False
        raise AttributeError(name)

    @staticmethod
    def numbers(values) -> list:
        """A numeric array as plain classes hold it: a list (typed arrays decode to array.array)."""
        return values if type(values) is list else list(values)

    @staticmethod
    def octet_list(data: bytes) -> bytes:
        return data

    @staticmethod
    def uint8_list(data: bytes) -> bytes:
        return data


class RosClasses:
    """Namespace of rclpy classes, each imported the first time a decoder needs it.

    A type with no importable rclpy class (ROS not installed, or a package only uwgen
    knows) falls back to its generated plain class, and says so once in the log.
    `C.fast_<key>` is true when the class of `key` and those of its nested (non-array)
    messages have the layout in `layouts`: decoders then fill their slots directly.
    """

    def __init__(self, imports: dict[str, tuple[str, str]], fallback: PlainClasses,
                 layouts: dict[str, tuple] | None = None, fast: bool = True):
        self._imports = imports
        self._fallback = fallback
        self._layouts = layouts or {}
        self._fast = fast
        # What rosidl's constructors put in `_check_fields` (the environment, read once).
        self.check_fields = os.environ.get("ROS_PYTHON_CHECK_FIELDS", "") == "1"

    def constructors_only(self) -> "RosClasses":
        """The same classes, every decoder using their constructors (the fallback)."""
        return RosClasses(self._imports, self._fallback, self._layouts, fast=False)

    def __getattr__(self, key: str):
        if key.startswith("fast_"):
            ok = self._fast and self._fast_ok(key[5:], set())
            setattr(self, key, ok)
            return ok
        try:
            module, name = self._imports[key]
        except KeyError:
            raise AttributeError(key) from None
        try:
            cls = importlib.import_module(module)
            for part in name.split("."):   # an action's parts: `Fibonacci.Goal`
                cls = getattr(cls, part)
        except (ImportError, AttributeError) as exc:
            cls = getattr(self._fallback, key)
            log.info("no rclpy class %s.%s (%s): decoding to the generated plain class", module, name, exc)
        setattr(self, key, cls)  # later look-ups are plain attribute reads
        return cls

    def _fast_ok(self, key: str, seen: set) -> bool:
        layout = self._layouts.get(key)
        if layout is None or key not in self._imports:
            return False
        cls = getattr(self, key)
        if cls is getattr(self._fallback, key, None):
            return False
        problem = layout_problem(cls, layout, self.check_fields)
        if problem:
            log.warning("rclpy's %s is not laid out as uwgen's fast decoders assume (%s): "
                        "its messages are built by its constructor", key, problem)
            return False
        seen.add(key)
        for _name, _rtype, store in layout:
            if store.startswith("msg:") and store[4:] not in seen:
                if not getattr(self, f"fast_{store[4:]}"):
                    return False
        return True

    @staticmethod
    def ndarray(values, dtype: str):
        """A fixed numeric array as rclpy keeps it: a numpy array of `dtype`."""
        import numpy
        return numpy.array(values, dtype=dtype)

    @staticmethod
    def array(values, code: str) -> array.array:
        """A numeric sequence as rclpy keeps it: an array.array of type `code` (a decoded
        typed array already is one, fresh: it is kept)."""
        if type(values) is array.array and values.typecode == code:
            return values
        return array.array(code, values)

    @staticmethod
    def numbers(values):
        """A numeric array for rclpy's constructors, which take a list or an array.array."""
        return values

    @staticmethod
    def octet_list(data: bytes) -> list[bytes]:
        """rclpy holds `byte[]` as a list of 1-byte bytes."""
        return [data[k:k + 1] for k in range(len(data))]

    @staticmethod
    def uint8_list(data: bytes) -> list[int]:
        return list(data)


_SCALARS = {"float": float, "int": int, "bool": bool, "bytes": bytes, "str": str}


def layout_problem(cls: type, layout: tuple, check_fields: bool) -> str:
    """What about rclpy class `cls` differs from `layout` ((name, rosidl type, store) per
    field, uwgen.codegen.rosidl_layout.ros_layout), or '' when decoders may fill its slots."""
    names = [name for name, _t, _s in layout]
    slots = list(getattr(cls, "__slots__", ()))
    if slots != [f"_{n}" for n in names] + ["_check_fields"]:
        return f"slots {slots}"
    types = getattr(cls, "_fields_and_field_types", None)
    if types != {name: rtype for name, rtype, _s in layout}:
        return f"field types {types}"
    if cls.__new__ is not object.__new__:
        return "a __new__ of its own"
    try:
        default = cls()
    except Exception as exc:   # noqa: BLE001 - any failure means: do not assume anything
        return f"its default constructor fails: {exc!r}"
    if getattr(default, "_check_fields", None) is not check_fields:
        return "check_fields not taken from ROS_PYTHON_CHECK_FIELDS"
    for name, _rtype, store in layout:
        value = getattr(default, f"_{name}")
        prop = getattr(cls, name, None)
        if not isinstance(prop, property) or getattr(default, name) is not value:
            return f"field {name} is not a property reading slot _{name}"
        if not holds(value, store):
            return f"slot _{name} holds {type(value).__name__}, not {store}"
    return ""


def holds(value, store: str) -> bool:
    """Whether `value` is what a slot of kind `store` (rosidl_layout.ros_store) holds."""
    kind, _, arg = store.partition(":")
    if kind in _SCALARS:
        return type(value) is _SCALARS[kind]
    if kind == "msg":
        return hasattr(type(value), "_fields_and_field_types")
    if kind == "list":
        return type(value) is list
    if kind == "array":
        return type(value) is array.array and value.typecode == arg
    if kind == "ndarray":
        return type(value).__name__ == "ndarray" and str(value.dtype) == arg
    return False
