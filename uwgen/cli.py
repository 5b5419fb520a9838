"""`uwgen` command line: each sub-command lives in its own module under uwgen.commands.

A command module defines `HELP` (one line), `add_arguments(parser)` and `run(args) -> int`.
Modules are imported only when their command runs, so `uwgen build` never loads rclpy.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys

from uwgen.commands.options import HelpFormatter, all_parsers

# name -> module; the order here is the order of `uwgen --help`.
COMMANDS = {
    "build": "uwgen.commands.build",
    "analyze": "uwgen.commands.analyze",
    "emulate": "uwgen.commands.emulate",
    "bridge": "uwgen.commands.bridge",
    "demo": "uwgen.commands.demo",
    "log": "uwgen.commands.log",
    "ros-interfaces": "uwgen.commands.ros_interfaces",
    "rmw-config": "uwgen.commands.rmw_config",
    "keygen": "uwgen.commands.keygen",
}

EXIT_USAGE = 2  # bad input: definitions, manifest, arguments


def _load(module_name: str):
    return importlib.import_module(module_name)


def version() -> str:
    """The installed distribution's version, else the package's own."""
    try:
        from importlib.metadata import PackageNotFoundError, version as dist_version
        return dist_version("uwgen")
    except PackageNotFoundError:
        from uwgen import __version__
        return __version__


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="uwgen",
        description="Generate CBOR codecs and bridge nodes that carry ROS 2 topics, services "
                    "and actions over DESERT underwater acoustic links.",
        epilog="Conventions of every command: -m MANIFEST is the manifest file or a folder\n"
               "holding uwgen.yaml; interface folders are DIR arguments; defaults are shown\n"
               "in each command's --help.")
    parser.add_argument("--version", action="version", version=f"uwgen {version()}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug detail")
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="log only warnings and errors (no INFO lines from any part)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module_name in COMMANDS.items():
        if only is not None and name != only:
            # Other commands are listed by name only; their modules are not imported.
            sub.add_parser(name, help=f"see `uwgen {name} --help`")
            continue
        try:
            module = _load(module_name)
        except ModuleNotFoundError as exc:
            if exc.name != module_name:
                raise
            continue  # command not available in this build
        cmd = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(cmd)
        cmd.set_defaults(_module=module)
    for p in all_parsers(parser):
        p.formatter_class = HelpFormatter
    return parser


def _innermost(parser: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.ArgumentParser:
    """The (sub-)command parser `args` were read by: `uwgen rmw-config import`'s, not uwgen's."""
    while True:
        sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        chosen = getattr(args, sub.dest, None) if sub is not None else None
        if chosen not in getattr(sub, "choices", {}):
            return parser
        parser = sub.choices[chosen]


def parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    """parse_args, but DIR arguments may also come after options that follow other positional
    arguments (`rmw-config import CONF --type N=T DIR`: argparse takes a command's positional
    arguments in one run and refused the DIR after --type as unrecognized, with uwgen's
    usage). Anything else unrecognized is refused by the command's own parser (exit 2)."""
    args, extra = parser.parse_known_args(argv)
    if not extra:
        return args
    command = _innermost(parser, args)
    folders = next((a for a in command._actions if a.dest == "folders"), None)
    if folders is None or any(a.startswith("-") for a in extra):
        command.error(f"unrecognized arguments: {' '.join(extra)}")
    convert = folders.type or (lambda text: text)
    args.folders = [*(args.folders or []), *(convert(a) for a in extra)]
    return args


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    first = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(first if first in COMMANDS else None)
    # A command that runs another program (`uwgen ros-interfaces DIR -- CMD ...`) gets
    # everything after the first `--` untouched.
    tail: list[str] = []
    module = sys.modules.get(COMMANDS.get(first or "", ""))
    if getattr(module, "TAKES_COMMAND", False) and "--" in argv:
        cut = argv.index("--")
        argv, tail = argv[:cut], argv[cut + 1:]
    args = parse(parser, argv)
    args.command_line = tail
    # A command's own --quiet (uwgen demo --quiet) is as quiet as the global one.
    quiet = args.quiet or getattr(args, "quiet_command", False)
    level = logging.DEBUG if args.verbose else logging.WARNING if quiet else logging.INFO
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s",
                        stream=sys.stderr)
    logging.getLogger().setLevel(level)   # also when something configured logging before
    if not getattr(args, "_module", None):
        parser.print_help()
        return EXIT_USAGE
    return int(args._module.run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
