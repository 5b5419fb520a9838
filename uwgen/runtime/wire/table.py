"""The codec table of a generated package: manifest id -> codec, plus class namespaces.

Generated modules hold the per-type `enc_*`/`dec_*` functions; this module wraps them
with the payload header (wire format section 3) and the profile's payload limits. The
two namespaces decoders build messages from, rclpy classes (imported on first use, so a
generated package imports without ROS) or the generated plain classes, are in
uwgen.runtime.wire.rosclasses.
"""
from __future__ import annotations

import importlib
import logging
from dataclasses import dataclass, field
from typing import Any, Callable

from uwgen.manifest.model import ACTION_HANDLES, RMW_DESERT, LinkPolicy, Qos, Side
from uwgen.runtime.wire.codec import (
    KIND_REQUEST, KIND_RESPONSE, KIND_TOPIC, MAX_SEQ, RMW_MAX_ITEMS, CodecError, DecodeError,
    EncodeError, load_items, pack_items, unexpected,
)
from uwgen.runtime.wire.framing import MAX_PAYLOAD
from uwgen.runtime.wire.rosclasses import PlainClasses, RosClasses

log = logging.getLogger("uwgen.codec")


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
    enc_slots: Callable[[Any, list], None] | None = None   # `enc` reading rclpy's slots
    # [the rclpy class enc_slots may encode, or None], filled at the first encode
    _slots_for: list = field(default_factory=list, compare=False, repr=False)

    def ros_class(self) -> type:
        return getattr(self.ros, self.class_key)

    def slots_class(self) -> type | None:
        """The class whose messages `encode` reads through `enc_slots`: the rclpy class,
        when RosClasses checked its layout and its nested classes' (as for the fast
        decoders), else None (every message is read field by field, by name)."""
        if not self._slots_for:
            ok = self.enc_slots is not None and getattr(self.ros, f"fast_{self.class_key}")
            self._slots_for.append(self.ros_class() if ok else None)
        return self._slots_for[0]

    def plain_class(self) -> type:
        return getattr(self.plain, self.class_key)

    def encode(self, msg: Any, header: list | None = None) -> bytes:
        """The payload: `header` items, then the message's fields. Without a header, the
        bytes of the bare message (its fields alone; `decode_message` reads them back)."""
        out = [] if header is None else header
        try:
            if type(msg) is (self._slots_for[0] if self._slots_for else self.slots_class()):
                n = len(out)
                try:
                    self.enc_slots(msg, out)
                except AttributeError:   # a nested value that is no rclpy message: by name
                    del out[n:]
                    self.enc(msg, out)
            else:
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

    def decode_message(self, payload: bytes, ros: bool = True) -> Any:
        """The message of `encode(msg)`'s bytes (a bare message, no header); `ros=False`:
        the generated plain class even where rclpy is importable."""
        return self.decode(payload, (), ros)[0]

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
    peers: tuple[str, ...] = ()        # the sides that take part (a fleet vehicle's entry); (): every side

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
    peers: tuple[str, ...] = ()        # the sides that take part (a fleet vehicle's entry); (): every side

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


def find_codec(codecs: dict, type_name: str, profile: str) -> TypeCodec:
    """codecs[(type_name, profile)], else a KeyError saying what the package has."""
    try:
        return codecs[(type_name, profile)]
    except KeyError:
        pass
    profiles = sorted(p for t, p in codecs if t == type_name)
    if profiles:
        raise KeyError(f"{type_name} has no {profile} codec in this package, only {', '.join(profiles)} "
                       f"(give profile=...)") from None
    raise KeyError(f"{type_name} has no codec in this package: the manifest may give it field "
                   f"encodings (use its entry in TOPICS, SERVICES or ACTIONS), or it was not built") from None


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
    mac: Any = None             # manifest.model.MacConfig; None: mode none (uwgen.runtime.link.mac)


# What follows an action's goal handle in a response (kind 3), wire format 13. Answers to a
# goal or a cancel are the goal's state after it; a result's status is followed by the
# result's fields. The numbers 1..6 are those of action_msgs/msg/GoalStatus.
REJECTED = 0         # the goal was not accepted
ACCEPTED = 1         # the goal was accepted
CANCEL_REFUSED = 2   # (EXECUTING) the cancel was refused: the goal goes on
CANCELING = 3        # the cancel was accepted
SUCCEEDED = 4
CANCELED = 5
ABORTED = 6
ANSWERS = (REJECTED, ACCEPTED, CANCEL_REFUSED, CANCELING)
RESULTS = (SUCCEEDED, CANCELED, ABORTED)
# What follows 24 + handle in a result status request (kind 2).
RESULT_RECEIVED = 0  # the client side has the goal's result: stop sending it
RESULT_WANTED = 1    # the client side has an accepted goal and no result: send it again


@dataclass(frozen=True)
class ActionCodec:
    """One action on one manifest id (wire format 13):

    - goal (client side -> server side): `[2, id, handle, goal fields...]`
    - cancel (client side -> server side): `[2, id, handle]`
    - answer (server side -> client side): `[3, id, handle, REJECTED|ACCEPTED|CANCEL_REFUSED|CANCELING]`
    - result (server side -> client side): `[3, id, handle, SUCCEEDED|CANCELED|ABORTED, result fields...]`
    - feedback (server side -> client side): `[0, id, handle, feedback fields...]`
    - result status (client side -> server side): `[2, id, 24 + handle, RESULT_RECEIVED|RESULT_WANTED]`
    """

    id: int
    name: str
    type_name: str
    server: str
    accept_timeout: float
    result_timeout: float
    max_goals: int
    profile: str
    policy: LinkPolicy            # goals and cancels; answers and results
    feedback_policy: LinkPolicy | None   # latest only; None: feedback is not sent
    goal: TypeCodec
    result: TypeCodec
    feedback: TypeCodec
    ros_import: tuple[str, str]
    fingerprint: bytes = b""      # schema fingerprint of this id, as for topics and services
    peers: tuple[str, ...] = ()   # the sides that take part (a fleet vehicle's entry); (): every side

    def ros_class(self) -> type:
        module, name = self.ros_import
        return getattr(importlib.import_module(module), name)

    # client side -> server side

    def encode_goal(self, handle: int, goal: Any) -> bytes:
        return self.goal.encode(goal, [KIND_REQUEST, self.id, _handle(handle)])

    def encode_cancel(self, handle: int) -> bytes:
        return pack_items([KIND_REQUEST, self.id, _handle(handle)])

    def encode_result_status(self, handle: int, received: bool) -> bytes:
        return pack_items([KIND_REQUEST, self.id, ACTION_HANDLES + _handle(handle),
                           RESULT_RECEIVED if received else RESULT_WANTED])

    def decode_result_status(self, payload: bytes) -> tuple[int, bool] | None:
        """(handle, received) when the payload is a result status request, else None (a
        goal or a cancel: decode_request reads it). Its third item is 24 + handle, above
        any handle (CBOR `18 18`..`18 2f`): a goal or a cancel has a handle 0..23 there (one
        byte), and, unsigned, the item is read by the security header (section 12) too."""
        at = 2 if len(payload) > 1 and payload[1] < 0x18 else 3
        if len(payload) <= at + 1 or payload[at] != 0x18:
            return None
        v = load_items(payload)
        if len(v) != 4 or v[:2] != [KIND_REQUEST, self.id] or type(v[2]) is not int \
                or type(v[3]) is not int or v[3] not in (RESULT_RECEIVED, RESULT_WANTED):
            raise DecodeError("status", f"not a result status request: {v!r}")
        return _handle(v[2] - ACTION_HANDLES, DecodeError), v[3] == RESULT_RECEIVED

    def decode_request(self, payload: bytes, ros: bool = True) -> tuple[int, Any]:
        """(handle, goal), or (handle, None) for a cancel."""
        head = self._header(payload, KIND_REQUEST, 3)
        if head is not None:
            return head[2], None
        msg, head = self.goal.decode(payload, (KIND_REQUEST, self.id, None), ros)
        return _handle(head[2], DecodeError), msg

    # server side -> client side

    def encode_answer(self, handle: int, answer: int) -> bytes:
        if answer not in ANSWERS:
            raise EncodeError("answer", f"{answer!r} is not an answer code {ANSWERS}")
        return pack_items([KIND_RESPONSE, self.id, _handle(handle), answer])

    def encode_result(self, handle: int, status: int, result: Any) -> bytes:
        if status not in RESULTS:
            raise EncodeError("status", f"{status!r} is not a terminal status {RESULTS}")
        return self.result.encode(result, [KIND_RESPONSE, self.id, _handle(handle), status])

    def decode_response(self, payload: bytes, ros: bool = True) -> tuple[int, int, Any]:
        """(handle, code, result): result is None for an answer (code in ANSWERS)."""
        head = self._header(payload, KIND_RESPONSE, 4)
        if head is not None:
            if head[3] not in ANSWERS:
                raise DecodeError("answer", f"{head[3]!r} is not an answer code {ANSWERS}")
            return head[2], head[3], None
        msg, head = self.result.decode(payload, (KIND_RESPONSE, self.id, None, None), ros)
        if head[3] not in RESULTS:
            raise DecodeError("status", f"{head[3]!r} is not a terminal status {RESULTS}")
        return _handle(head[2], DecodeError), head[3], msg

    def encode_feedback(self, handle: int, feedback: Any) -> bytes:
        return self.feedback.encode(feedback, [KIND_TOPIC, self.id, _handle(handle)])

    def decode_feedback(self, payload: bytes, ros: bool = True) -> tuple[int, Any]:
        msg, head = self.feedback.decode(payload, (KIND_TOPIC, self.id, None), ros)
        return _handle(head[2], DecodeError), msg

    def _header(self, payload: bytes, kind: int, n: int) -> list | None:
        """The items of a payload that is only a header of `n` unsigned items (a cancel,
        an answer), else None (a goal or a result: its codec decodes it)."""
        v = load_items(payload)
        if len(v) != n:
            return None
        for k, got in enumerate(v):
            want = (kind, self.id)[k] if k < 2 else None
            if type(got) is not int or (want is not None and got != want) or got < 0:
                raise DecodeError(("kind", "id", "handle", "code")[k], f"unexpected item {got!r}")
        _handle(v[2], DecodeError)
        return v


def _handle(handle: int, error: type = EncodeError) -> int:
    if type(handle) is not int or not 0 <= handle < ACTION_HANDLES:
        raise error("handle", f"expected a goal handle 0..{ACTION_HANDLES - 1}, got {handle!r}")
    return handle
