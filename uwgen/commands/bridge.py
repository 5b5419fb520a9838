"""`uwgen bridge`: run one side's bridge node against its DESERT node.

    uwgen bridge -m msg_samples/uwgen.yaml --side vehicle [--port 4001] [--host 127.0.0.1]
    uwgen bridge -m msg_samples/uwgen.yaml --side surface --package-dir generated \\
        --ros-args -p period:=0.5

The manifest names the generated package (`package:`, default `uwgen_<network>`), which
is imported from --package-dir, else from the `generated/` folder next to the manifest or
above it (where `uwgen build` wrote it), else ./generated. A package built from another
version of the manifest or of its definitions is refused, with the command that rebuilds
it. Same as `python -m <package>.bridge_<side>` (which does not check).
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from types import ModuleType

import yaml

from uwgen import safefile, yamltext
from uwgen.bridge.main import EXIT_USAGE, add_link_arguments
from uwgen.bridge.plan import PlanError, import_package
from uwgen.commands.options import add_manifest

HELP = "run the bridge node of one manifest side against its DESERT node"

log = logging.getLogger("uwgen.bridge")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_manifest(parser, required=True)
    parser.add_argument("--side", required=True, help="which side of the manifest to bridge")
    parser.add_argument("--package-dir", type=Path, default=None,
                        help="folder holding the generated package (default: generated/ in the "
                             "manifest's folder or a folder above it, else ./generated)")
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
        data = yamltext.safe_load(yamltext.read(manifest, "manifest"))
    except safefile.UnreadableFile as exc:
        raise PlanError(exc.message) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{manifest}:{mark.line + 1}:{mark.column + 1}" if mark else str(manifest)
        raise PlanError(f"{where}: not valid YAML: {getattr(exc, 'problem', exc)}") from None
    if not isinstance(data, dict) or not isinstance(data.get("network"), str):
        raise PlanError(f"{manifest}:1:1: a manifest needs a `network` name")
    return str(data.get("package") or f"uwgen_{data['network']}").replace("-", "_")


def candidate_dirs(manifest: Path, given: Path | None) -> list[Path]:
    """Where the generated package may be: --package-dir alone if given, else `generated/`
    in the manifest's folder and each folder above it (the project `uwgen build` ran in),
    then ./generated."""
    if given is not None:
        return [Path(given)]
    folder = Path(manifest).resolve().parent
    dirs = [d / "generated" for d in (folder, *folder.parents)]
    here = (Path.cwd() / "generated").resolve()
    return dirs + ([here] if here not in dirs else [])


def find_package(name: str, manifest: Path, given: Path | None = None) -> ModuleType:
    """Import the generated package `name` from the first candidate folder that holds it."""
    dirs = candidate_dirs(manifest, given)
    for d in dirs:
        try:
            there = (d / name / "__init__.py").is_file()
        except OSError:         # --package-dir with a name too long for the system, say
            there = False
        if there:
            loaded = sys.modules.get(name)
            if loaded is not None and Path(loaded.__file__).parent.parent != d.resolve():
                for mod in [m for m in sys.modules if m == name or m.startswith(name + ".")]:
                    del sys.modules[mod]    # a package of that name from elsewhere
            return import_package(name, d)
    looked = ", ".join(str(d) for d in dirs[:4]) + (f" and {len(dirs) - 4} more up to /" if len(dirs) > 4 else "")
    raise PlanError(f"generated package {name!r} not found: looked for {name}/ in {looked}; "
                    f"run `uwgen build -m {manifest}` in your project folder first"
                    if given is None else
                    f"generated package {name!r} not found in {safefile.shown(given)}: run `uwgen build` first")


def check_fresh(package: ModuleType, manifest: Path) -> None:
    """Refuse a package built from another version of the manifest or its definitions."""
    from uwgen.buildinfo import stale_message

    if getattr(package, "BUILT_FROM", None) is None:
        log.warning("%s records no build inputs (built by an older uwgen): cannot check that it "
                    "matches %s; rebuild it with `uwgen build`", Path(package.__file__).parent, manifest)
        return
    problem = stale_message(package, manifest)
    if problem:
        raise PlanError(problem)


def run(args: argparse.Namespace) -> int:
    from uwgen.bridge.main import catch_stop_signals, restore_signals, run as run_bridge
    # Before the generated package (and with it rclpy's messages) is imported: a SIGINT
    # while starting stops the bridge cleanly instead of raising KeyboardInterrupt.
    stop, previous = catch_stop_signals()
    try:
        try:
            name = package_name(args.manifest)
            package = find_package(name, args.manifest, args.package_dir)
            check_fresh(package, args.manifest)
        except PlanError as exc:
            print(f"uwgen bridge: {exc}", file=sys.stderr)
            return EXIT_USAGE
        ros_args = ["--ros-args", *args.ros_args] if args.ros_args else []
        return run_bridge(package, args.side, args, ros_args, stop=stop)
    finally:
        restore_signals(previous)
