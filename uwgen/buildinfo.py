"""What a generated package was built from, and whether that still holds.

`uwgen build` writes `BUILT_FROM` into a generated package that has a manifest:

    BUILT_FROM = {
        "manifest": "<sha256 prefix of the manifest file>",
        "sources": {"turtlesim/msg/Pose.msg": "<sha256 prefix>",            # next to the manifest
                    "share/geometry_msgs/msg/Twist.msg": "<sha256 prefix>"},  # an installed package
        "root": "..",                         # where to run the command, from the manifest's folder
        "command": "uwgen build msg_samples", # the build that makes this package again (-o aside)
    }

Paths of local definitions are relative to the manifest's folder, installed ones are
looked up under `share/` of sys.prefix and AMENT_PREFIX_PATH, so the record is the same
on every machine. `uwgen bridge -m MANIFEST` calls `stale_reasons` and refuses a package
whose manifest or definitions changed since it was built.
"""
from __future__ import annotations

import hashlib
import os
import shlex
from pathlib import Path
from typing import Iterable

DIGEST_CHARS = 16


def file_digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:DIGEST_CHARS]


def _key(path: Path, local: bool, base: Path) -> str:
    if local:
        return Path(os.path.relpath(Path(path).resolve(), base.resolve())).as_posix()
    return "share/" + "/".join(Path(path).parts[-3:])


def make_record(manifest: Path, sources: Iterable[tuple[Path, bool]], root: Path,
                command: list[str]) -> dict:
    """The record of a build: `sources` are (definition file, is local) pairs; `command`
    (without -o: the record does not depend on where the package is written) ran in `root`."""
    base = Path(manifest).parent
    return {
        "manifest": file_digest(manifest),
        "sources": dict(sorted((_key(p, local, base), file_digest(p)) for p, local in sources)),
        "root": Path(os.path.relpath(Path(root).resolve(), base.resolve())).as_posix(),
        "command": shlex.join(command),
    }


def _installed(key: str) -> Path | None:
    import sys
    prefixes = [sys.prefix, *[p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]]
    for prefix in prefixes:
        path = Path(prefix) / key
        if path.is_file():
            return path
    return None


def stale_reasons(record: dict, manifest: Path) -> list[str]:
    """What differs between the build's record and the files now (empty: still fresh)."""
    reasons = []
    try:
        if file_digest(manifest) != record["manifest"]:
            reasons.append(f"{manifest} changed")
    except OSError as exc:
        reasons.append(f"{manifest}: cannot read: {exc.strerror}")
    base = Path(manifest).parent
    for key, digest in record.get("sources", {}).items():
        path = _installed(key) if key.startswith("share/") else base / key
        if path is None or not path.is_file():
            reasons.append(f"{key} is gone")
        elif file_digest(path) != digest:
            reasons.append(f"{path} changed")
    return reasons


def rebuild_hint(record: dict, manifest: Path, package_dir: Path) -> str:
    """The command that builds the package again into `package_dir`, with the folder to run it in."""
    root = (Path(manifest).parent / record.get("root", ".")).resolve()
    package_dir = Path(package_dir).resolve()
    command = record.get("command", "uwgen build")
    local = any(not key.startswith("share/") for key in record.get("sources", {}))
    if local and "--ros" not in shlex.split(command):
        command += " --ros"   # interfaces of its own: rclpy needs their type support rebuilt too
    if package_dir != root / "generated" / package_dir.name:
        command += f" -o {shlex.quote(str(package_dir))}"
    return f"cd {shlex.quote(str(root))} && {command}"


def stale_message(package, manifest: Path) -> str | None:
    """Why the generated `package` (module) does not match `manifest` and the definitions
    now, with the command that rebuilds it; None when it matches (or records nothing)."""
    record = getattr(package, "BUILT_FROM", None)
    if record is None:
        return None
    pkg_dir = Path(package.__file__).parent
    reasons = stale_reasons(record, manifest)
    if not reasons:
        return None
    shown = "; ".join(reasons[:5]) + (f"; and {len(reasons) - 5} more" if len(reasons) > 5 else "")
    return (f"{pkg_dir} is stale: it was built from other files than these ({shown}). "
            f"Build it again: {rebuild_hint(record, manifest, pkg_dir)}")


def own_manifest(package) -> Path | None:
    """The manifest a package in <root>/generated/<package> was built from, if it is there."""
    source = getattr(getattr(package, "MANIFEST", None), "source", None)
    if not source or getattr(package, "BUILT_FROM", None) is None:
        return None
    root = Path(package.__file__).resolve().parent.parent.parent
    candidate = root / source
    # The record says where the build ran relative to the manifest: both must agree.
    if candidate.is_file() and (candidate.parent / package.BUILT_FROM.get("root", ".")).resolve() == root:
        return candidate
    return None
