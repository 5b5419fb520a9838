"""`uwgen` command line: each sub-command lives in its own module under uwgen.commands.

A command module defines `HELP` (one line), `add_arguments(parser)` and `run(args) -> int`.
Modules are imported only when their command runs, so `uwgen build` never loads rclpy.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys

# name -> module; the order here is the order of `uwgen --help`.
COMMANDS = {
    "build": "uwgen.commands.build",
    "analyze": "uwgen.commands.analyze",
    "emulate": "uwgen.commands.emulate",
    "bridge": "uwgen.commands.bridge",
    "demo": "uwgen.commands.demo",
    "rmw-config": "uwgen.commands.rmw_config",
    "keygen": "uwgen.commands.keygen",
}

EXIT_USAGE = 2  # bad input: definitions, manifest, arguments


def _load(module_name: str):
    return importlib.import_module(module_name)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="uwgen",
        description="Generate CBOR codecs and bridge nodes that carry ROS 2 topics and "
                    "services over DESERT underwater acoustic links.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug detail")
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
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    first = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(first if first in COMMANDS else None)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    if not getattr(args, "_module", None):
        parser.print_help()
        return EXIT_USAGE
    return int(args._module.run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
