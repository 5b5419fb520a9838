"""The codec table of a generated package: manifest id -> codec, plus class namespaces.

Generated modules hold the per-type `enc_*`/`dec_*` functions; this module wraps them
with the payload header (wire format section 3) and the profile's payload limits, and
provides the two namespaces decoders build messages from: rclpy classes (imported on
first use, so a generated package imports without ROS) or the generated plain classes.
"""
from __future__ import annotations

import importlib
import logging
from dataclasses import dataclass
from typing import Any, Callable

from uwgen.manifest.model import RMW_DESERT, LinkPolicy, Qos, Side
from uwgen.runtime.codec import (
    KIND_REQUEST, KIND_RESPONSE, KIND_TOPIC, MAX_SEQ, RMW_MAX_ITEMS, CodecError, DecodeError,
    EncodeError, load_items, pack_items, unexpected,
)
from uwgen.runtime.framing import MAX_PAYLOAD

log = logging.getLogger("uwgen.codec")


class PlainClasses:
    """Namespace of the generated plain classes, as decoders name them (`C.pkg__Name`)."""

    def __init__(self, classes: dict[str, type]):
        self.__dict__.update(classes)

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
    """

    def __init__(self, imports: dict[str, tuple[str, str]], fallback: PlainClasses):
        self._imports = imports
        self._fallback = fallback

    def __getattr__(self, key: str):
        try:
            module, name = self._imports[key]
        except KeyError:
            raise AttributeError(key) from None
        try:
            cls = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError) as exc:
            cls = getattr(self._fallback, key)
            log.info("no rclpy class %s.%s (%s): decoding to the generated plain class", module, name, exc)
        setattr(self, key, cls)  # later look-ups are plain attribute reads
        return cls

    @staticmethod
    def octet_list(data: bytes) -> list[bytes]:
        """rclpy holds `byte[]` as a list of 1-byte bytes."""
        return [data[k:k + 1] for k in range(len(data))]

    @staticmethod
    def uint8_list(data: bytes) -> list[int]:
        return list(data)


@dataclass(frozen=True)
class TypeCodec:
    """One message type's codec under one profile."""

    type_name: str                     # pkg/msg/Name
    profile: str
    enc: Callable[[Any, list], None]
    dec: Callable[[list, int, Any], tuple[Any, int]]
    plain: PlainClasses
    ros: RosClasses
    class_key: str                     # attribute of the namespaces for this type

    def ros_class(self) -> type:
        return getattr(self.ros, self.class_key)

    def plain_class(self) -> type:
        return getattr(self.plain, self.class_key)

    def encode(self, msg: Any, header: list) -> bytes:
        """The payload: `header` items, then the message's fields."""
        out = header
        try:
            self.enc(msg, out)
        except CodecError:
            raise
        except AttributeError as exc:
            raise EncodeError(getattr(exc, "name", "") or "",
                              f"{type(msg).__name__} is not a {self.type_name}: {exc}") from None
        except TypeError as exc:
            raise EncodeError("", f"cannot encode {self.type_name}: {exc}") from None
        data = pack_items(out)
        if self.profile == RMW_DESERT:
            if len(out) > RMW_MAX_ITEMS:
                raise EncodeError("", f"{len(out)} CBOR items: an rmw_desert receiver keeps only {RMW_MAX_ITEMS}")
            if len(data) > MAX_PAYLOAD:
                raise EncodeError("", f"{len(data)}-byte payload: over the {MAX_PAYLOAD} bytes an rmw_desert "
                                      "receiver takes (no fragmentation in this profile)")
        return data

    def decode(self, payload: bytes, header: tuple, ros: bool = True) -> tuple[Any, list]:
        """(message, header items). `header` gives the expected kind and id; a header
        item given as None (a service seq) is returned, not compared."""
        v = load_items(payload)
        n = len(header)
        if len(v) < n:
            raise DecodeError("", f"payload has {len(v)} items, fewer than its {n}-item header")
        for k, want in enumerate(header):
            got = v[k]
            if want is None:
                if type(got) is not int or not 0 <= got <= MAX_SEQ:
                    raise DecodeError("seq", f"expected an unsigned sequence number, got {got!r}")
            elif type(got) is not int or got != want:
                raise DecodeError(("kind", "id")[k] if k < 2 else "header",
                                  f"expected {want}, got {got!r}")
        try:
            msg, i = self.dec(v, n, self.ros if ros else self.plain)
        except DecodeError:
            raise
        except Exception as exc:  # the decoder is total: nothing else escapes
            raise unexpected(self.type_name, exc) from None
        if i != len(v):
            raise DecodeError("", f"{len(v) - i} items left over after the last field of {self.type_name}")
        return msg, v[:n]


@dataclass(frozen=True)
class TopicCodec:
    id: int
    name: str
    type_name: str
    publisher: str
    policy: LinkPolicy
    qos: Qos
    profile: str
    codec: TypeCodec
    fingerprint: bytes = b""           # schema fingerprint of this id (wire format section 10)

    def ros_class(self) -> type:
        return self.codec.ros_class()

    def encode(self, msg: Any) -> bytes:
        return self.codec.encode(msg, [KIND_TOPIC, self.id])

    def decode(self, payload: bytes, ros: bool = True) -> Any:
        return self.codec.decode(payload, (KIND_TOPIC, self.id), ros)[0]


@dataclass(frozen=True)
class ServiceCodec:
    id: int
    name: str
    type_name: str
    server: str
    timeout: float
    policy: LinkPolicy
    profile: str
    request: TypeCodec
    response: TypeCodec
    ros_import: tuple[str, str]
    fingerprint: bytes = b""           # schema fingerprint of this id (wire format section 10)

    def ros_class(self) -> type:
        module, name = self.ros_import
        return getattr(importlib.import_module(module), name)

    def encode_request(self, seq: int, req: Any) -> bytes:
        return self.request.encode(req, [KIND_REQUEST, self.id, _seq(seq)])

    def decode_request(self, payload: bytes, ros: bool = True) -> tuple[int, Any]:
        msg, head = self.request.decode(payload, (KIND_REQUEST, self.id, None), ros)
        return head[2], msg

    def encode_response(self, seq: int, resp: Any) -> bytes:
        return self.response.encode(resp, [KIND_RESPONSE, self.id, _seq(seq)])

    def decode_response(self, payload: bytes, ros: bool = True) -> tuple[int, Any]:
        msg, head = self.response.decode(payload, (KIND_RESPONSE, self.id, None), ros)
        return head[2], msg


def _seq(seq: int) -> int:
    if type(seq) is not int or not 0 <= seq <= MAX_SEQ:
        raise EncodeError("seq", f"expected an unsigned sequence number, got {seq!r}")
    return seq


@dataclass(frozen=True)
class ManifestInfo:
    """What the generated package keeps of its manifest."""

    network: str
    profile: str
    sides: dict[str, Side]
    fragment_id: int | None
    source: str
    schema_id: int | None = None       # reserved id of schema announcements (None: not announced)
    schema_period: float | None = None  # seconds between periodic announcements (None: none)
    schema_digest: bytes = b""         # fingerprint of the whole manifest (wire format section 10)
    security: Any = None        # manifest.model.SecurityPlan when anything is protected
