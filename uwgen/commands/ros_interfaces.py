"""`uwgen ros-interfaces`: build rclpy type support for your own interface packages.

    uwgen ros-interfaces interfaces                      # every package in the folder
    uwgen ros-interfaces interfaces/auv_msgs             # one package
    uwgen ros-interfaces interfaces -- python3 talker.py # then run a program that uses them

Runs ROS's own rosidl generators (CMake and a C compiler must be installed) once per
version of each package's .msg/.srv files and keeps the result in uwgen's cache
($UWGEN_CACHE, else $XDG_CACHE_HOME/uwgen, else ~/.cache/uwgen), never in the source
tree. `uwgen bridge` finds these builds by itself; a program of yours that imports the
messages runs after `--`, with its environment set up for them. See docs/walkthrough.md.
"""
from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

HELP = "build rclpy type support for the interface packages in folders (cached), or run a program with it"
TAKES_COMMAND = True   # everything after `--` is the program to run

ENV_KEYS = ("PYTHONPATH", "AMENT_PREFIX_PATH", "LD_LIBRARY_PATH")   # what --print-env prints
from uwgen.safefile import shown
from uwgen.typesupport import BuildError

EXIT_FAILED = 1     # the type support build itself failed (the toolchain, not the input)
EXIT_USAGE = 2      # bad input: no such folder, no package in it, a broken definition


class InputError(BuildError):
    """The folders given are not interface packages, or their definitions are broken."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folders", nargs="+", type=Path, metavar="DIR",
                        help="an interface package (with msg/, srv/ or action/) or a folder of packages")
    parser.add_argument("--cache", type=Path, default=None, metavar="DIR",
                        help="cache folder (default: $UWGEN_CACHE, else $XDG_CACHE_HOME/uwgen, "
                             "else ~/.cache/uwgen)")
    parser.add_argument("--prune", action="store_true",
                        help="also remove the cached builds of earlier versions of these packages")
    parser.add_argument("--print-env", action="store_true",
                        help="print the three variables a program needs to import them "
                             "(PYTHONPATH, AMENT_PREFIX_PATH, LD_LIBRARY_PATH; sh syntax)")
    parser.usage = ("uwgen ros-interfaces [-h] [--cache DIR] [--prune] [--print-env] DIR [DIR ...] "
                    "[-- PROGRAM [ARG ...]]")
    parser.epilog = "After `--`: a program to run with the packages importable, e.g. -- python3 talker.py"


def ensure_folders(folders: list[Path], cache: Path | None = None, quiet: bool = True):
    """Build (or reuse) every package in `folders`; returns their InterfaceEnvs."""
    from uwgen.typesupport import ensure_interfaces, local_dependencies, package_dirs

    envs = []
    for folder in folders:
        try:
            is_dir = Path(folder).is_dir()
        except OSError as exc:      # a name too long for the system, say
            raise InputError(f"{shown(folder)}: cannot be looked at: {exc.strerror or exc}") from None
        if not is_dir:
            raise InputError(f"{shown(folder)}: no such folder")
        found = package_dirs(folder)
        if not found:
            raise InputError(f"{folder}: no interface package here (expected msg/, srv/ or action/ in it "
                             "or in its sub-folders)")
        with_deps = list(dict.fromkeys([*found, *(d for p in found for d in local_dependencies(p))]))
        _check_definitions([d for d in with_deps if (d / "msg").is_dir() or (d / "srv").is_dir()])
        for package_dir in found:
            envs.append(ensure_interfaces(package_dir, cache, quiet))
    return envs


def _check_definitions(package_dirs: list[Path]) -> None:
    """uwgen's own parser first: broken definitions get `file:line:column` errors, not a CMake log."""
    from uwgen.errors import Collector
    from uwgen.idl.loader import InterfaceLibrary
    from uwgen.idl.model import DefinitionError
    errors = Collector()
    try:
        lib = InterfaceLibrary(package_dirs) if package_dirs else None
        if lib is None:
            return
        for name in lib.local_names():
            with errors.attempt(DefinitionError):
                lib.get(name)
    except DefinitionError as exc:
        errors.add(exc)
    if errors:
        raise InputError("\n".join(str(e) for e in errors.errors))


def run(args: argparse.Namespace) -> int:
    try:
        envs = ensure_folders(args.folders, args.cache)
    except InputError as exc:
        print(f"uwgen ros-interfaces: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except BuildError as exc:
        print(f"uwgen ros-interfaces: {exc}", file=sys.stderr)
        return EXIT_FAILED
    if args.prune:
        from uwgen.typesupport import package_dirs, prune
        for folder in args.folders:
            for package_dir in package_dirs(folder):
                for gone in prune(package_dir, args.cache):
                    print(f"removed {gone}", file=sys.stderr)
    env = dict(os.environ)
    for e in envs:
        env = e.child_env(env)
    command = getattr(args, "command_line", [])
    if args.print_env:
        for key in ENV_KEYS:   # all three, as the program needs them (not only what changed)
            if env.get(key):
                print(f"export {key}={shlex.quote(env[key])}")
    elif not command:
        for e in envs:
            where = e.prefix if e.prefix is not None else "installed"
            print(f"{e.package}: {where}")
    if not command:
        return 0
    sys.stdout.flush()
    sys.stderr.flush()
    try:   # the program replaces this process: signals and exit status are its own
        os.execvpe(command[0], command, env)
    except OSError as exc:
        print(f"uwgen ros-interfaces: cannot run {command[0]!r}: {exc.strerror}", file=sys.stderr)
        return EXIT_USAGE
