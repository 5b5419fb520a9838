"""What a ROS 2 interface definition says, independent of how it is encoded.

The parser (`uwgen.idl.parser`) produces these objects from `.msg` and `.srv` files;
the manifest resolves type names to them; the codec IR (`uwgen.codegen.ir`) is built
from them. Nothing here knows about CBOR.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Union

# Primitive type names of the .msg language, after alias resolution
# (`char` is uint8 in ROS 2's .msg language; `byte` stays `byte`, an octet).
INTEGER_RANGES: dict[str, tuple[int, int]] = {
    "byte": (0, 0xFF),
    "char": (0, 0xFF),
    "uint8": (0, 0xFF),
    "int8": (-0x80, 0x7F),
    "uint16": (0, 0xFFFF),
    "int16": (-0x8000, 0x7FFF),
    "uint32": (0, 0xFFFFFFFF),
    "int32": (-0x80000000, 0x7FFFFFFF),
    "uint64": (0, 0xFFFFFFFFFFFFFFFF),
    "int64": (-0x8000000000000000, 0x7FFFFFFFFFFFFFFF),
}
FLOAT_TYPES = ("float32", "float64")
STRING_TYPES = ("string", "wstring")
PRIMITIVE_TYPES = ("bool", *INTEGER_RANGES, *FLOAT_TYPES, *STRING_TYPES)
# Element types whose arrays travel as one CBOR byte string in profile `native`.
OCTET_TYPES = ("byte", "char", "uint8")


class ArrayKind(Enum):
    NONE = "none"            # a single value
    FIXED = "fixed"          # T[N]
    BOUNDED = "bounded"      # T[<=N]
    UNBOUNDED = "unbounded"  # T[]


@dataclass(frozen=True)
class FieldType:
    """The type of one field: a primitive or a nested message, maybe an array of it.

    `base` is a primitive name from PRIMITIVE_TYPES or a full message name
    `pkg/msg/Name`. `string_bound` is N of `string<=N` (None when unbounded).
    `size` is N of `T[N]` or `T[<=N]` (None otherwise).
    """

    base: str
    array: ArrayKind = ArrayKind.NONE
    size: int | None = None
    string_bound: int | None = None

    @property
    def is_primitive(self) -> bool:
        return self.base in PRIMITIVE_TYPES

    @property
    def is_array(self) -> bool:
        return self.array is not ArrayKind.NONE

    def element(self) -> "FieldType":
        """The type of one element (self when not an array)."""
        return FieldType(self.base, ArrayKind.NONE, None, self.string_bound)

    def __str__(self) -> str:  # the .msg spelling, with full message names
        text = self.base
        if self.string_bound is not None:
            text += f"<={self.string_bound}"
        if self.array is ArrayKind.FIXED:
            text += f"[{self.size}]"
        elif self.array is ArrayKind.BOUNDED:
            text += f"[<={self.size}]"
        elif self.array is ArrayKind.UNBOUNDED:
            text += "[]"
        return text


@dataclass(frozen=True)
class SourceRef:
    """Where something was defined: for `file:line:column: message` errors."""

    path: Path
    line: int
    column: int = 1

    def __str__(self) -> str:
        return f"{self.path}:{self.line}:{self.column}"


# A default or constant value: bool, int, float, str, or a tuple of those for arrays.
Value = Union[bool, int, float, str, tuple]


@dataclass(frozen=True)
class Field:
    name: str
    type: FieldType
    default: Value | None = None
    where: SourceRef | None = None


@dataclass(frozen=True)
class Constant:
    name: str
    type: str  # a primitive name; constants cannot be arrays or messages
    value: Value
    where: SourceRef | None = None


@dataclass
class MessageDef:
    """One message: `pkg/msg/Name`, a service's `pkg/srv/Name_Request`/`_Response`, or an
    action's `pkg/action/Name_Goal`/`_Result`/`_Feedback`."""

    package: str
    name: str
    fields: list[Field] = field(default_factory=list)
    constants: list[Constant] = field(default_factory=list)
    source: Path | None = None
    namespace: str = "msg"  # "msg", "srv" for a service's request/response, "action" for an action's parts

    @property
    def full_name(self) -> str:
        return f"{self.package}/{self.namespace}/{self.name}"

    def nested_types(self) -> list[str]:
        """Full names of the message types this one's fields use, in field order."""
        seen: dict[str, None] = {}
        for f in self.fields:
            if not f.type.is_primitive:
                seen.setdefault(f.type.base)
        return list(seen)


@dataclass
class ServiceDef:
    package: str
    name: str
    request: MessageDef
    response: MessageDef
    source: Path | None = None

    @property
    def full_name(self) -> str:
        return f"{self.package}/srv/{self.name}"


@dataclass
class ActionDef:
    """An action: goal, result and feedback messages (`pkg/action/Name_Goal`, ...)."""

    package: str
    name: str
    goal: MessageDef
    result: MessageDef
    feedback: MessageDef
    source: Path | None = None

    @property
    def full_name(self) -> str:
        return f"{self.package}/action/{self.name}"

    @property
    def parts(self) -> list[MessageDef]:
        return [self.goal, self.result, self.feedback]


ACTION_PARTS = ("Goal", "Result", "Feedback")

InterfaceDef = Union[MessageDef, ServiceDef, ActionDef]


class DefinitionError(Exception):
    """A problem in an interface definition, located as `file:line:column: message`."""

    def __init__(self, where: SourceRef | str | None, message: str):
        self.where = where
        self.message = message
        super().__init__(f"{where}: {message}" if where else message)
