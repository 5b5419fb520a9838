"""`uwgen rmw-config`: rmw_desert's id table from a manifest, a manifest from an id table.

    uwgen rmw-config export -m MANIFEST [DIR ...] [-o FILE] [--include-native]
    uwgen rmw-config import CONF [DIR ...] --side-of NAME=SIDE ... [--type NAME=TYPE ...] -o FILE
    uwgen rmw-config beacons -m MANIFEST [DIR ...] --side SIDE [--frames]

DIR: folders of interface packages, as in every command (-I DIR, the old spelling, still works).

Exit status 0 on success, 2 on bad input (with a message saying what and where).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from uwgen.argtypes import number, whole
from uwgen.commands.options import add_folders, add_manifest, old_spelling

HELP = "write rmw_desert's ros_allowed_topics.conf from a manifest, or start a manifest from one"
EXIT_OK = 0
EXIT_USAGE = 2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION")

    exp = sub.add_parser("export", help="write ros_allowed_topics.conf (JSON) for a manifest",
                         description="Write rmw_desert's id table for MANIFEST. With profile "
                                     "rmw_desert it holds /discovery (1), /discovery_request "
                                     "(2) and the rmw_desert topics and services.")
    _manifest_args(exp, "export")
    exp.add_argument("-o", "--output", type=Path, metavar="FILE",
                     help="write here instead of standard output")
    exp.add_argument("--include-native", action="store_true",
                     help="also list native-profile entries (rmw_desert nodes would misread them)")
    exp.add_argument("--force", action="store_true",
                     help="replace FILE if it exists with other content (as import needs it)")

    imp = sub.add_parser(
        "import", help="start a manifest (profile rmw_desert) from ros_allowed_topics.conf",
        description="Start a manifest from rmw_desert's id table. Names and ids come from "
                    "CONF; every name needs its type (--type, --types, or a well-known name) "
                    "and the side that publishes or serves it (--side-of or --default-side).")
    imp.add_argument("conf", type=Path, metavar="CONF", help="ros_allowed_topics.conf to read")
    add_folders(imp, "folders of interface packages (besides the output's folder and the installed ones)")
    _old_interfaces(imp, "import")
    imp.add_argument("-o", "--output", type=Path, metavar="FILE", required=True,
                     help="manifest to write (e.g. <folder>/uwgen.yaml)")
    imp.add_argument("--side-of", action="append", default=[], metavar="NAME=SIDE",
                     help="the side whose ROS graph publishes topic NAME or serves service NAME")
    imp.add_argument("--default-side", metavar="SIDE",
                     help="side of every name without --side-of")
    imp.add_argument("--side", action="append", default=[], metavar="SIDE=PORT",
                     help="DESERT port (or HOST:PORT) of a side; default 4000, 4001, ... in "
                          "order of first mention")
    imp.add_argument("--type", action="append", default=[], metavar="NAME=TYPE",
                     help="type of NAME: pkg/msg/Type, pkg/srv/Type, pkg/Type, or a bare "
                          "Type when only one package has it")
    imp.add_argument("--types", type=Path, metavar="FILE",
                     help="YAML/JSON mapping of names to types (used where --type is not given)")
    imp.add_argument("--no-builtin-hints", action="store_true",
                     help="do not take types of well-known names (turtlesim, /chatter, ...)")
    imp.add_argument("--network", default="rmw_desert", help="network name (default rmw_desert)")
    imp.add_argument("--max-read-length", type=whole(1, 4096), default=64,
                     help="DESERT max_read_length written for every side (default 64)")
    imp.add_argument("--period", type=number(0.001, 3600), default=1.0,
                     help="DESERT period_ in seconds written for every side (default 1.0)")
    imp.add_argument("--force", action="store_true", help="overwrite FILE if it exists")

    bea = sub.add_parser("beacons", help="show the beacons a side's bridge announces",
                         description="List the rmw_desert discovery beacons the bridge of "
                                     "SIDE sends for MANIFEST.")
    _manifest_args(bea, "beacons")
    bea.add_argument("--side", required=True, help="the bridge's side")
    bea.add_argument("--node", help="node name announced (default uwgen_<side>)")
    bea.add_argument("--frames", action="store_true", help="also print each framed beacon in hex")


def _manifest_args(parser: argparse.ArgumentParser, action: str) -> None:
    add_manifest(parser, required=True)
    add_folders(parser, "folders of interface packages (besides the manifest's folder and the "
                        "installed ones)")
    _old_interfaces(parser, action)


def _old_interfaces(parser: argparse.ArgumentParser, action: str) -> None:
    # Interface folders are DIR arguments in every command; -I DIR was this command's own.
    old_spelling(parser, ("-I", "--interfaces"), "a DIR argument", "old_interfaces",
                 f"rmw-config {action}", append=True, type=Path, metavar="DIR")


def _folders(args) -> list[Path]:
    return [*args.folders, *(getattr(args, "old_interfaces", None) or [])]


def run(args: argparse.Namespace) -> int:
    from uwgen.idl.model import DefinitionError
    from uwgen.interop.beacons import BeaconError
    from uwgen.interop.rmw_config import RmwConfigError
    from uwgen.manifest.loader import ManifestError

    action = getattr(args, "action", None)
    if action is None:
        _err("say what to do: export, import or beacons (see `uwgen rmw-config --help`)")
        return EXIT_USAGE
    try:
        return {"export": _export, "import": _import, "beacons": _beacons}[action](args)
    except (RmwConfigError, ManifestError, DefinitionError, BeaconError) as exc:
        _err(str(exc))
        return EXIT_USAGE


def _err(message: str) -> None:
    print(f"uwgen rmw-config: error: {message}", file=sys.stderr)


def _load(manifest_arg: Path, interfaces: list[Path]):
    from uwgen.interop.rmw_config import RmwConfigError
    from uwgen.manifest.loader import MANIFEST_NAME, find_manifest, load_manifest

    path = manifest_arg
    if path.is_dir():
        found = find_manifest(path)
        if found is None:
            raise RmwConfigError(f"{path} has no {MANIFEST_NAME}")
        path = found
    elif not path.exists():
        raise RmwConfigError(f"{path}: no such manifest")
    return load_manifest(path, _library(path.parent, interfaces))


def _has_interfaces(folder: Path) -> bool:
    """True when `folder` is an interface package or holds some (the library's rule)."""
    def is_package(p: Path) -> bool:
        return (p / "msg").is_dir() or (p / "srv").is_dir()
    return folder.is_dir() and (is_package(folder) or any(
        is_package(child) for child in folder.iterdir() if child.is_dir()))


def _library(home: Path, interfaces: list[Path]):
    """Interfaces of the manifest's (or output's) folder if it has any, of -I, installed."""
    from uwgen.idl.loader import InterfaceLibrary

    folders = ([home] if _has_interfaces(home) else []) + list(interfaces)
    return InterfaceLibrary(folders=folders, installed=True)


def _export(args) -> int:
    from uwgen.interop.rmw_config import export_conf

    manifest = _load(args.manifest, _folders(args))
    result = export_conf(manifest, include_native=args.include_native)
    for note in result.omitted:
        print(f"uwgen rmw-config: left out {note}", file=sys.stderr)
    if args.output is None:
        sys.stdout.write(result.text)
    elif _unchanged(args.output, result.text, args.force):
        print(f"{args.output} is up to date: {len(result.table)} names", file=sys.stderr)
    else:
        _write(args.output, result.text)
        print(f"wrote {args.output}: {len(result.table)} names", file=sys.stderr)
    return EXIT_OK


def _unchanged(path: Path, text: str, force: bool) -> bool:
    """True when `path` already holds `text`; RmwConfigError when it holds something else
    and `force` is not given (a table another tool or a person wrote is not lost silently)."""
    from uwgen import safefile
    from uwgen.interop.rmw_config import CONF_LIMIT, RmwConfigError

    if not os.path.lexists(path):
        return False
    try:
        if safefile.read_text(path, "output", CONF_LIMIT) == text:
            return True
    except safefile.UnreadableFile as exc:
        if not force:
            raise RmwConfigError(f"{exc}; not replacing it") from None
    if not force:
        raise RmwConfigError(f"{path} exists with other content; pass --force to overwrite it")
    return False


def _pairs(values: list[str], option: str) -> dict[str, str]:
    from uwgen.interop.rmw_config import RmwConfigError

    out: dict[str, str] = {}
    for value in values:
        key, sep, rest = value.partition("=")
        if not sep or not key or not rest:
            raise RmwConfigError(f"{option} {value!r}: expected NAME=VALUE")
        if key in out and out[key] != rest:
            raise RmwConfigError(f"{option} gives {key} twice ({out[key]} and {rest})")
        out[key] = rest
    return out


def _sides(args, side_of: dict[str, str]):
    from uwgen.interop.rmw_config import RmwConfigError, SideSpec
    from uwgen.manifest.loader import SIDE_NAME

    given = _pairs(args.side, "--side")
    order: list[str] = list(given)
    for side in [*side_of.values(), *([args.default_side] if args.default_side else [])]:
        if side not in order:
            order.append(side)
    specs: list[SideSpec] = []
    for name in order:
        if not SIDE_NAME.fullmatch(name):
            raise RmwConfigError(f"side name '{name}' must be letters, digits and '_', "
                                 "starting with a letter")
        if name in given:
            host, _, port_text = given[name].rpartition(":")
            try:
                port = int(port_text)
            except ValueError:
                port = 0
            if not 1 <= port <= 65535:
                raise RmwConfigError(f"--side {name}={given[name]}: expected PORT or HOST:PORT")
            specs.append(SideSpec(name, port, host or "127.0.0.1"))
        else:
            taken = {s.port for s in specs}
            port = 4000
            while port in taken:
                port += 1
            specs.append(SideSpec(name, port))
    return specs


def _import(args) -> int:
    from uwgen.interop.rmw_config import (
        RESERVED, RmwConfigError, manifest_from_conf, read_conf, read_hints, resolve_types)
    from uwgen.manifest.loader import load_manifest

    table = read_conf(args.conf)
    names = [n for n in table if n not in RESERVED]
    side_of = _pairs(args.side_of, "--side-of")
    unknown = sorted(set(side_of) - set(names))
    if unknown:
        raise RmwConfigError(f"--side-of names what is not in {args.conf}: {', '.join(unknown)}")
    if args.default_side:
        for name in names:
            side_of.setdefault(name, args.default_side)
    out = args.output
    if out.exists() and not args.force:
        raise RmwConfigError(f"{out} exists; pass --force to overwrite it")
    lib = _library(out.parent, _folders(args))
    hints = read_hints(args.types) if args.types else {}
    types = resolve_types(names, lib, _pairs(args.type, "--type"), hints,
                          builtin=not args.no_builtin_hints)
    text = manifest_from_conf(table, types=types, side_of=side_of, sides=_sides(args, side_of),
                              network=args.network, source=str(args.conf),
                              max_read_length=args.max_read_length, period=args.period)
    # Prove it loads before it replaces anything: a manifest we wrote must never be broken.
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=".uwgen-import-", suffix=".yaml", dir=out.parent)
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        manifest = load_manifest(tmp, lib)
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    print(f"wrote {out}: {len(manifest.topics)} topics, {len(manifest.services)} services, "
          f"sides {', '.join(manifest.sides)}; review the types and link settings",
          file=sys.stderr)
    return EXIT_OK


def _beacons(args) -> int:
    from uwgen.interop.beacons import encode_beacon
    from uwgen.interop.discovery import bridge_beacons
    from uwgen.interop.rmw_config import RmwConfigError
    from uwgen.runtime.wire.framing import encode_frame

    manifest = _load(args.manifest, _folders(args))
    if args.side not in manifest.sides:
        raise RmwConfigError(f"side {args.side!r} is not in the manifest "
                             f"(sides: {', '.join(manifest.sides)})")
    beacons = bridge_beacons(manifest, args.side, node_name=args.node)
    if not beacons:
        print("no topic or service uses profile rmw_desert: nothing to announce")
        return EXIT_OK
    for b in beacons:
        payload = encode_beacon(b)
        print(f"{b.entity.name.lower():<10} {b.topic}  {b.type_name}  gid {b.gid.hex()}  "
              f"({len(payload)} bytes)")
        if args.frames:
            print("  " + encode_frame(payload).hex(" ").upper())
    return EXIT_OK


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
