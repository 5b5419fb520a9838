"""Frame sizes of the demo's topics, measured: one representative message as the manifest
sends it next to the same message in profile native (the report's "frame sizes" line)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class FrameSize:
    """Bytes on the wire of one representative message of a topic."""
    topic: str
    native: int            # frame bytes in profile native without field encodings, unprotected
    sent: int              # frame bytes as the manifest sends it (security included)
    how: str               # 'packed + field encodings', ...
    security: str = "off"  # sign | encrypt | off
    security_bytes: int = 0   # of `sent`, what the secure link adds (sync frames: 13 more)




def frame_sizes(manifest: Path, folders: list[Path]) -> list[FrameSize]:
    """Frame bytes of a representative /turtle1/cmd_vel and /turtle1/pose as `manifest`
    sends them, next to the same messages in profile native without field encodings
    (codecs built for the occasion, so the numbers follow the manifest). On an envelope link (no
    rmw_desert entry) a frame is the message alone in a packet's envelope, sealed as the
    bridge seals packets when the topic is protected (one tag; a sync packet has 13 bytes
    more); on wire format 1 the payload sealed as its bridge seals it. Measured, under a
    throwaway key."""
    import tempfile

    from uwgen.bridge.plan import is_rmw_desert
    from uwgen.codegen import generate
    from uwgen.runtime.wire import envelope as env
    from uwgen.runtime.wire.framing import OVERHEAD
    from uwgen.security import packetwire, wire
    from uwgen.security.keys import new_epoch, new_master_key, working_key

    samples = {
        "/turtle1/cmd_vel": lambda cls: cls(linear=_vec(cls, 0.4), angular=_vec(cls, 0.0, z=0.3)),
        "/turtle1/pose": lambda cls: cls(x=5.54, y=7.12, theta=1.571, linear_velocity=0.4, angular_velocity=0.0),
    }
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        pkg = generate(Path(tmp), "uwgen_demo_sizes", folders=folders, manifest=manifest,
                       names=["geometry_msgs/msg/Twist", "turtlesim/msg/Pose"])
        plan = getattr(pkg.MANIFEST, "security", None)
        modes = dict(plan.modes) if plan is not None else {}
        v2 = not any(is_rmw_desert(e) for e in (*pkg.TOPICS.values(), *pkg.SERVICES.values()))
        aead = wire.new_aead(working_key(new_master_key(), "sizes", 1, new_epoch()))
        for topic in pkg.TOPICS.values():
            if topic.name not in samples:
                continue
            msg = samples[topic.name](topic.codec.plain_class())
            native = pkg.codec(topic.type_name, "native").encode(msg, [0, topic.id])
            encoded = any(c is topic.codec for c in getattr(pkg, "VARIANTS", {}).values())
            how = topic.profile + (" + field encodings" if encoded else "")
            payload = topic.encode(msg)
            mode = modes.get(topic.id, "off")
            fingerprint = bytes(getattr(topic, "fingerprint", b"") or b"")
            if v2:
                body = env.strip_packed_head(payload) if topic.profile == "packed" else payload
                alone = env.Envelope(1, 1, (env.from_v1(body),))
                plain = alone.encode()
                sent = plain if not modes else packetwire.seal(     # a secured link seals every packet
                    aead, alone, 1, lambda m: modes.get(m.id) == wire.ENCRYPT, lambda i: fingerprint)
                out.append(FrameSize(topic.name, OVERHEAD + env.HEAD + env.v1_message_size(native, True),
                                     len(sent) + OVERHEAD, how, mode, len(sent) - len(plain)))
                continue
            sent = payload
            if mode != "off":
                sent = wire.seal(aead, mode, 1, 1, payload, fingerprint)
            out.append(FrameSize(topic.name, len(native) + OVERHEAD, len(sent) + OVERHEAD, how, mode,
                                 len(sent) - len(payload)))
    return out


def _vec(twist_cls, x: float, z: float = 0.0):
    """A Vector3 of the plain Twist class's package (its default value's class)."""
    v = type(twist_cls().linear)()
    v.x, v.z = x, z
    return v

