"""The bridge's side of the secure link: one side's seal, from its plan and options.

On a wire format 2 link (profiles native and packed) it is a `PacketSeal`, whose packet hooks
seal each packet with one tag (docs/wire-format.md section 12.2); on a wire format 1 link a
`LinkGuard`, which seals each payload (section 12). Both have `stats()` and `close()`.

The generated package's `MANIFEST.security` (a SecurityPlan, None when nothing is
protected) names the key file, every side's sender id and the protected ids. The key
file is `--key-file` if given, else the manifest's `key_file` (a relative path is taken
from the folder of the manifest the bridge was given, else of the one next to the
package's project, else as the build named it). The guard keeps no state on disk (a fresh
epoch per start); it holds a lock, `--security-state` if given, else
`<key file>.<network>.<side>.lock` next to the key, so a second copy of the same side on this
machine is refused at start. An entry's max age on the secure link is its ttl, or for a
service its timeout and for an action its accept_timeout (`reliability.max_ages`).
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from uwgen.bridge.plan import BridgeOptions, BridgePlan, PlanError
from uwgen.bridge.reliability import max_ages
from uwgen.manifest.model import DEFAULT_TAG_BYTES
from uwgen.runtime.clock import SYSTEM_CLOCK, Clock
from uwgen.safefile import shown

log = logging.getLogger("uwgen.security")


def key_path(plan: BridgePlan, options: BridgeOptions) -> Path:
    return _key_place(plan, options)[0]


def _key_place(plan: BridgePlan, options: BridgeOptions) -> tuple[Path, str]:
    """(the key file's path, how it was found from what was written) for messages."""
    sec = plan.security
    if options.key_file is not None:
        return Path(options.key_file), "given with --key-file"
    written = f"the manifest's key_file {shown(sec.key_file)!r}"
    path = Path(sec.key_file).expanduser()
    how = ["'~' expanded to the home folder"] if str(path) != str(sec.key_file) else []
    if not path.is_absolute():
        base = (plan.manifest_path.parent if plan.manifest_path is not None else
                Path(plan.manifest_source).parent if plan.manifest_source else None)
        if base is not None:
            path = base / path
            how.append(f"taken relative to the manifest's folder {shown(base)}")
        else:
            how.append("taken relative to the current folder")
    return path, written + (f" ({', '.join(how)})" if how else "")


def _missing_key(plan: BridgePlan, options: BridgeOptions, path: Path) -> str:
    """What to do about a key file that is not there: get the network's key, never make a
    new one here (a bridge with another key can talk to nobody on the network)."""
    where = _key_place(plan, options)[1]
    return (f"key file {shown(path)} not found ({where}): copy the network's key file there from a "
            f"machine of this network, or give its place with --key-file. Every side must hold "
            f"the same key: a new one (uwgen keygen) is only for setting up a new network")


def lock_path(key_file: Path, network: str, side: str) -> Path:
    """`<key file>.<network>.<side>.lock`, next to the key file."""
    key_file = Path(key_file)
    return key_file.with_name(f"{key_file.name}.{network}.{side}.lock")


def check_security(plan: BridgePlan, options: BridgeOptions) -> None:
    """Fail early, before ROS starts, with a clear message (PlanError) if the key is unusable."""
    if plan.security is None:
        return
    from uwgen.security.keys import KeyFileMissing, SecurityError, read_key_file
    if plan.side not in plan.security.senders:
        raise PlanError(f"side {plan.side!r} has no sender_id in the manifest's security set-up")
    path = key_path(plan, options)
    try:
        read_key_file(path)
    except KeyFileMissing:
        raise PlanError(_missing_key(plan, options, path)) from None
    except SecurityError as exc:
        raise PlanError(str(exc)) from None


def guard_for(plan: BridgePlan, options: BridgeOptions, clock: Clock = SYSTEM_CLOCK) -> Any:
    """This side's PacketSeal (wire format 2) or LinkGuard (wire format 1), or None when the
    manifest protects nothing."""
    sec = plan.security
    if sec is None:
        return None
    from uwgen.security.guard import GuardConfig, LinkGuard
    from uwgen.security.packet_seal import PacketSeal
    from uwgen.security.keys import SecurityError, key_id, read_key_file
    check_security(plan, options)
    path = key_path(plan, options)
    try:
        master = read_key_file(path)
        # Every topic and service of the network, the fleet's others included: a packet of the
        # shared channel may carry other vehicles' ids, all in its authenticated data.
        entries = {e.id: e for e in (*plan.topics, *plan.services,
                                     *getattr(plan, "overheard_topics", ()),
                                     *getattr(plan, "overheard_services", ()))}
        # a topic's ttl; a service's ttl, else its timeout; an action's ttl, else its
        # accept_timeout: the same max ages as the link's staleness (docs/seams.md section 8)
        ttls = max_ages(plan)
        config = GuardConfig(
            network=plan.network, sender=sec.senders[plan.side],
            peers={sid: side for side, sid in sec.senders.items() if side != plan.side},
            modes=dict(sec.modes),
            fingerprints={i: bytes(getattr(sec, "seal_fingerprints", {}).get(i)
                                   or getattr(entries.get(i), "fingerprint", b"") or b"")
                          for i in sec.modes},
            max_ages={i: float(t) for i, t in ttls.items() if i in sec.modes},
            tag_bytes=getattr(sec, "tag_bytes", DEFAULT_TAG_BYTES))
        lock = (Path(options.security_state) if options.security_state is not None
                else lock_path(path, plan.network, plan.side))
        if plan.wire_format == 2:
            guard = PacketSeal.for_key(master, config, lock, clock=clock, name=plan.side,
                                       fragment_id=plan.fragment_id)
        else:
            guard = LinkGuard.for_key(master, config, lock, clock=clock, name=plan.side)
    except SecurityError as exc:
        raise PlanError(str(exc)) from None
    protected = ", ".join(f"{i} ({m})" for i, m in sorted(sec.modes.items()))
    log.info("[%s] secure link (%s): sender %d, epoch %s; protects ids %s; key %s (key id %s, the "
             "same on every side); lock %s", plan.side,
             f"one {config.tag_bytes}-byte tag per packet" if plan.wire_format == 2
             else "one tag per payload", config.sender,
             guard.stats()["epoch"], protected, path, key_id(master, plan.network), lock)
    return guard


def link_security(guard: Any) -> tuple[dict[str, Any], Any]:
    """(Link keyword arguments, packet hooks) for `guard_for`'s result: a LinkGuard goes to the
    link as `guard`; a PacketSeal gives its hooks (the bridge joins them with reliability's)."""
    if guard is None:
        return {}, None
    hooks = getattr(guard, "hooks", None)
    if hooks is not None:
        return {}, hooks()
    return {"guard": guard}, None
