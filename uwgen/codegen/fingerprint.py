"""Schema fingerprints: one short hash per manifest id of everything that shapes its bytes.

Two sides that disagree about an id's type, profile or field encodings misread each
other silently; MAVLink guards against this with CRC_EXTRA, DCCL with its hash codec.
uwgen computes, at build time, for every topic, service and action of the manifest:

    fingerprint = SHA-256(canonical CBOR of the id's description)[:FINGERPRINT_BYTES]

The description (wire-format.md section 10) is the CBOR array

    ["uwgen-schema", 2, entry, kinds, id, profile, type name, roots, types, wire format]

plus, only for an id the secure link protects, an eleventh item: its security mode ("sign" or
"encrypt"), so two builds that protect an id differently refuse each other (the description,
and so the fingerprint, of an unprotected id is what it always was); and after it, only when
the manifest's `security: {tag_bytes}` is not the default 8, a twelfth: the tag length, so two
builds whose packets carry tags of different lengths disagree too (with the default, the
fingerprints are those of earlier builds).

where `entry` is "topic", "service" or "action", `kinds` the header kinds the id travels
with ([0], [2, 3] for a service, [0, 2, 3] for an action), `roots` the codec keys of the
message(s) (request then response for a service; goal, result, feedback for an action) and `types` every codec type they reach (inlined or through
arrays), sorted by key, and `wire format` 1 or the envelope's version (wire-format.md
section 14: 4 unless an entry of the manifest is in profile rmw_desert), each written generically: a dataclass becomes a map of its
fields plus "@": its class name (leaving out fields marked `metadata={"schema": False}`,
which name generated code and not bytes), an Enum its value, a list/tuple an array. Any IR
node class added later is therefore covered without being named here.

The canonical form is cbor2's `canonical=True` (RFC 7049 section 3.9: shortest integer
and float forms, definite lengths, map keys sorted by length then bytes), so the same
inputs give the same bytes on every machine and run.
"""
from __future__ import annotations

import dataclasses
import hashlib
from decimal import Decimal
from enum import Enum
from fractions import Fraction
from typing import Any, Iterable

import cbor2

from uwgen.codegen.ir import CodecType, variant_name
from uwgen.manifest.model import DEFAULT_TAG_BYTES
from uwgen.runtime.wire.codec import KIND_REQUEST, KIND_RESPONSE, KIND_TOPIC
from uwgen.runtime.wire.envelope import VERSION as ENVELOPE_VERSION

FINGERPRINT_BYTES = 4      # 2**-32 chance that two different schemas look alike (docs section 10)
SCHEMA_MAGIC = "uwgen-schema"
SCHEMA_VERSION = 2         # 2: the wire format version is item 9


def canonical(value: Any, where: str = "") -> Any:
    """`value` as plain CBOR-able data (dicts, lists, str, int, float, bytes, bool, None).

    Raises TypeError for a value with no stable form (so a new kind of IR value is noticed
    at build time instead of hashing something like an object address)."""
    if value is None or isinstance(value, (bool, int, float, str, bytes)):
        return value
    if isinstance(value, Enum):
        return canonical(value.value, where)
    if isinstance(value, Fraction):
        return {"@": "Fraction", "n": value.numerator, "d": value.denominator}
    if isinstance(value, Decimal):
        return {"@": "Decimal", "v": str(value)}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out = {"@": type(value).__name__}
        for f in dataclasses.fields(value):
            if f.metadata.get("schema") is False:   # names code, not bytes (CodecType.variant)
                continue
            out[f.name] = canonical(getattr(value, f.name), f"{where}.{f.name}")
        return out
    if isinstance(value, (list, tuple)):
        return [canonical(v, f"{where}[{k}]") for k, v in enumerate(value)]
    if isinstance(value, (set, frozenset)):
        items = [canonical(v, where) for v in value]
        return sorted(items, key=lambda v: cbor2.dumps(v, canonical=True))
    if isinstance(value, dict):
        return {canonical(k, where): canonical(v, f"{where}[{k!r}]") for k, v in value.items()}
    raise TypeError(f"schema fingerprint: no canonical form for {type(value).__name__} at "
                    f"{where or 'the root'}; teach uwgen.codegen.fingerprint.canonical about it")


def description(entry: str, kinds: Iterable[int], ident: int, profile: str, type_name: str,
                roots: list[CodecType], codecs: dict[str, CodecType], *,
                wire: int = ENVELOPE_VERSION, security: str = "off",
                tag_bytes: int = DEFAULT_TAG_BYTES) -> list:
    """The CBOR-able description of one manifest id (see the module docstring).

    `codecs` maps codec key -> CodecType for this profile; every type the roots reach
    through `uses` (message arrays) is included, inlined types are part of each tree."""
    reached: dict[str, CodecType] = {}
    todo = list(roots)
    while todo:
        ct = todo.pop()
        if ct.key in reached:
            continue
        reached[ct.key] = ct
        todo.extend(codecs[key] for key in ct.uses)
    types = [canonical(reached[key], key) for key in sorted(reached)]
    out = [SCHEMA_MAGIC, SCHEMA_VERSION, entry, list(kinds), ident, profile, type_name,
           [ct.key for ct in roots], types, wire]
    if security == "off":
        return out
    return [*out, security] if tag_bytes == DEFAULT_TAG_BYTES else [*out, security, tag_bytes]


def digest(data: Any) -> bytes:
    """SHA-256 of the canonical CBOR of `data`, truncated to FINGERPRINT_BYTES."""
    return hashlib.sha256(cbor2.dumps(data, canonical=True)).digest()[:FINGERPRINT_BYTES]


def topic_fingerprint(ident: int, profile: str, type_name: str, root: CodecType,
                      codecs: dict[str, CodecType], wire: int = ENVELOPE_VERSION,
                      security: str = "off", tag_bytes: int = DEFAULT_TAG_BYTES) -> bytes:
    return digest(description("topic", [KIND_TOPIC], ident, profile, type_name, [root], codecs,
                              wire=wire, security=security, tag_bytes=tag_bytes))


def service_fingerprint(ident: int, profile: str, type_name: str, request: CodecType,
                        response: CodecType, codecs: dict[str, CodecType],
                        wire: int = ENVELOPE_VERSION, security: str = "off", tag_bytes: int = DEFAULT_TAG_BYTES) -> bytes:
    return digest(description("service", [KIND_REQUEST, KIND_RESPONSE], ident, profile, type_name,
                              [request, response], codecs, wire=wire, security=security,
                              tag_bytes=tag_bytes))


def action_fingerprint(ident: int, profile: str, type_name: str, goal: CodecType,
                       result: CodecType, feedback: CodecType,
                       codecs: dict[str, CodecType], wire: int = ENVELOPE_VERSION,
                       security: str = "off", tag_bytes: int = DEFAULT_TAG_BYTES) -> bytes:
    return digest(description("action", [KIND_TOPIC, KIND_REQUEST, KIND_RESPONSE], ident, profile,
                              type_name, [goal, result, feedback], codecs, wire=wire,
                              security=security, tag_bytes=tag_bytes))


def package_digest(fingerprints: dict[tuple[str, int], bytes]) -> bytes:
    """One fingerprint of a whole manifest: of the sorted (entry, id, fingerprint) triples."""
    rows = [[entry, ident, fp] for (entry, ident), fp in sorted(fingerprints.items())]
    return digest([SCHEMA_MAGIC, SCHEMA_VERSION, "package", rows])


def entry_codecs(manifest: Any, builder: Any) -> dict[tuple[str, int], tuple[list[CodecType], dict[str, CodecType]]]:
    """('topic' | 'service' | 'action', id) -> (root codec types, every codec type they reach
    by key),
    as `builder` (an IRBuilder) makes them for the manifest's entries.

    These must be the codec types the entries' generated codecs are lowered from (a test
    checks the encoder names): whoever gives an entry its own codec variant (e.g. field
    encodings) picks it here too, so its fingerprint covers it."""
    out = {}
    for topic in manifest.topics:
        codecs = {ct.key: ct for ct in builder.codecs_for(topic.type, topic.profile)}
        root = builder.codec(topic.type, topic.profile, topic.fields, variant_name("t", topic.id, topic.fields))
        out[("topic", topic.id)] = ([root], codecs)
    for service in manifest.services:
        codecs: dict[str, CodecType] = {}
        for msg in (service.type.request, service.type.response):
            codecs.update({ct.key: ct for ct in builder.codecs_for(msg, service.profile)})
        roots = [builder.codec(service.type.request, service.profile, service.request_fields,
                               variant_name("q", service.id, service.request_fields)),
                 builder.codec(service.type.response, service.profile, service.response_fields,
                               variant_name("r", service.id, service.response_fields))]
        out[("service", service.id)] = (roots, codecs)
    for action in getattr(manifest, "actions", ()):
        codecs = {}
        for msg in action.type.parts:
            codecs.update({ct.key: ct for ct in builder.codecs_for(msg, action.profile)})
        roots = [builder.codec(msg, action.profile) for msg in action.type.parts]
        out[("action", action.id)] = (roots, codecs)
    return out


def wire_format_of(manifest: Any) -> int:
    """The wire format the manifest's links speak: 1 when an entry is in profile rmw_desert
    (its links keep wire format 1), else the envelope's version this build speaks
    (`envelope.VERSION`), so two builds of different envelopes tell each other apart."""
    entries = (*manifest.topics, *manifest.services, *getattr(manifest, "actions", ()))
    if any(getattr(e, "profile", "native") == "rmw_desert" for e in entries):
        return 1
    return ENVELOPE_VERSION


def manifest_fingerprints(manifest: Any, builder: Any,
                          tag_bytes: int | None = None) -> dict[tuple[str, int], bytes]:
    """('topic' | 'service' | 'action', id) -> fingerprint for every entry of `manifest` (with
    the manifest's tag length, or `tag_bytes`)."""
    entries = {**{("topic", t.id): t for t in manifest.topics},
               **{("service", s.id): s for s in manifest.services},
               **{("action", a.id): a for a in getattr(manifest, "actions", ())}}
    out: dict[tuple[str, int], bytes] = {}
    wire = wire_format_of(manifest)
    tag = (tag_bytes if tag_bytes is not None else
           getattr(getattr(manifest, "security", None), "tag_bytes", DEFAULT_TAG_BYTES))
    for key, (roots, codecs) in entry_codecs(manifest, builder).items():
        entry = entries[key]
        mode = getattr(entry, "security", "off")
        if key[0] == "topic":
            out[key] = topic_fingerprint(entry.id, entry.profile, entry.type_name, roots[0], codecs,
                                         wire, mode, tag)
        elif key[0] == "action":
            out[key] = action_fingerprint(entry.id, entry.profile, entry.type_name, *roots, codecs,
                                          wire, mode, tag)
        else:
            out[key] = service_fingerprint(entry.id, entry.profile, entry.type_name, *roots, codecs,
                                           wire, mode, tag)
    return out


def seal_fingerprints(manifest: Any, builder: Any) -> dict[int, bytes]:
    """Protected id -> the fingerprint the per-packet seal authenticates (wire-format.md 12.2),
    only when the manifest's tag is not the default: the description without its tag item.
    CCM binds the tag length into the tag itself, so a side built with another length can
    still tell a genuine packet of another length apart (security/taglength.py). Empty with
    the default tag: the seal then authenticates the announced fingerprints, as before."""
    security = getattr(manifest, "security", None)
    if getattr(security, "tag_bytes", DEFAULT_TAG_BYTES) == DEFAULT_TAG_BYTES:
        return {}
    protected = {e.id for e in (*manifest.topics, *manifest.services, *getattr(manifest, "actions", ()))
                 if getattr(e, "security", "off") != "off"}
    base = manifest_fingerprints(manifest, builder, DEFAULT_TAG_BYTES)
    return {ident: fp for (_, ident), fp in sorted(base.items()) if ident in protected}
