"""`uwgen bridge`: run one side's bridge node against its DESERT node.

    uwgen bridge -m msg_samples/uwgen.yaml --side vehicle [--port 4001] [--host 127.0.0.1]
    uwgen bridge -m msg_samples/uwgen.yaml --side surface --package-dir generated \\
        --ros-args -p period:=0.5

The manifest names the generated package (`package:`, default `uwgen_<network>`), which
is imported from --package-dir (default: ./generated, else the project's generated/).
Same as `python -m <package>.bridge_<side>`.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import yaml

from uwgen.bridge.main import EXIT_USAGE, add_link_arguments
from uwgen.bridge.plan import PlanError, import_package

HELP = "run the bridge node of one manifest side against its DESERT node"

PROJECT_GENERATED = Path(__file__).resolve().parents[2] / "generated"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-m", "--manifest", type=Path, required=True, help="the manifest (YAML)")
    parser.add_argument("--side", required=True, help="which side of the manifest to bridge")
    parser.add_argument("--package-dir", type=Path, default=None,
                        help="folder holding the generated package (default ./generated, "
                             "else the project's generated/)")
    add_link_arguments(parser)
    parser.add_argument("--ros-args", nargs=argparse.REMAINDER, dest="ros_args", metavar="ARG",
                        help="everything after it goes to rclpy (e.g. --ros-args -p period:=0.5); "
                             "must come last")


def package_name(manifest: Path) -> str:
    """The generated package's name, read from the manifest (`package`, else uwgen_<network>).

    Only these two keys are read: `uwgen build` validated the rest when it generated the
    package, and the package carries everything the bridge needs.
    """
    try:
        data = yaml.safe_load(manifest.read_text(encoding="utf-8"))
    except OSError as exc:
        raise PlanError(f"{manifest}: cannot read: {exc.strerror}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{manifest}:{mark.line + 1}:{mark.column + 1}" if mark else str(manifest)
        raise PlanError(f"{where}: not valid YAML: {getattr(exc, 'problem', exc)}") from None
    if not isinstance(data, dict) or not isinstance(data.get("network"), str):
        raise PlanError(f"{manifest}:1:1: a manifest needs a `network` name")
    return str(data.get("package") or f"uwgen_{data['network']}").replace("-", "_")


def resolve_package_dir(given: Path | None) -> Path:
    if given is not None:
        return given
    here = Path("generated")
    return here if here.is_dir() else PROJECT_GENERATED


def run(args: argparse.Namespace) -> int:
    from uwgen.bridge.main import run as run_bridge
    try:
        name = package_name(args.manifest)
        package = import_package(name, resolve_package_dir(args.package_dir))
    except PlanError as exc:
        print(f"uwgen bridge: {exc}", file=sys.stderr)
        return EXIT_USAGE
    ros_args = ["--ros-args", *args.ros_args] if args.ros_args else []
    return run_bridge(package, args.side, args, ros_args)
