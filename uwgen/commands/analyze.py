"""`uwgen analyze`: bits per field, bytes and air time per message, and the link budget."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from uwgen.argtypes import number
from uwgen import safefile
from uwgen.commands.options import add_folders, add_manifest
from uwgen.idl.model import DefinitionError
from uwgen.manifest.loader import MANIFEST_NAME, ManifestError

HELP = "show what each topic and service costs on the link: bits per field, bytes, air time, link budget"
EXIT_INPUT = 2
EXIT_OVER = 1


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_folders(p, "folders of interfaces the manifest's types come from (installed ones are found too)")
    add_manifest(p, help=f"default: DIR/{MANIFEST_NAME} of the first DIR, else ./{MANIFEST_NAME}")
    p.add_argument("--bitrate", type=number(1, 1e9), default=None, metavar="BPS",
                   help="the modem's bit rate for air times (default 4800 bit/s, DESERT's default modem)")
    p.add_argument("--json", action="store_true", help="print the analysis as JSON (for tools)")
    p.add_argument("--strict", action="store_true",
                   help="exit 1 when the configured traffic cannot fit a side's link")


def run(args: argparse.Namespace) -> int:
    from uwgen.analyze import DEFAULT_BITRATE, analyze
    from uwgen.analyze_report import format_analysis, to_json
    from uwgen.idl.loader import InterfaceLibrary
    from uwgen.linkfloor import check_read_lengths
    from uwgen.manifest.loader import load_manifest

    folders = list(args.folders)
    manifest_path = args.manifest or ((folders[0] / MANIFEST_NAME) if folders else Path(MANIFEST_NAME))
    parent = manifest_path.parent
    why = safefile.problem(manifest_path, "manifest")
    if why is not None:          # a name too long, a loop, a device: said as it is
        print(f"uwgen analyze: {why}", file=sys.stderr)
        return EXIT_INPUT
    if not manifest_path.is_file():
        print(f"uwgen analyze: no manifest at {safefile.shown(manifest_path)} (give one with -m)",
              file=sys.stderr)
        return EXIT_INPUT
    if not folders and (any(parent.glob("*/msg/*.msg")) or any(parent.glob("*/srv/*.srv"))):
        folders = [parent]   # interfaces next to the manifest, as `uwgen build` keeps them
    bitrate = args.bitrate if args.bitrate is not None else DEFAULT_BITRATE
    if not bitrate > 0:
        print(f"uwgen analyze: --bitrate must be > 0, got {bitrate:g}", file=sys.stderr)
        return EXIT_INPUT
    try:
        lib = InterfaceLibrary(folders, installed=True)
        manifest = load_manifest(manifest_path, lib)
        check_read_lengths(manifest)
        result = analyze(manifest, lib.get, bitrate)
    except (ManifestError, DefinitionError) as exc:
        print(f"uwgen analyze: {exc}", file=sys.stderr)
        return EXIT_INPUT
    if args.json:
        print(json.dumps(to_json(result), indent=1))
    else:
        print(format_analysis(result, {s.name: s.link.max_read_length for s in manifest.sides.values()}))
    over = any(b.typical > b.capacity or (b.worst is not None and b.worst > b.capacity) for b in result.budgets)
    return EXIT_OVER if args.strict and over else 0
