"""The command line's one way of saying things, shared by every command.

- `-m/--manifest MANIFEST`: the manifest file, or a folder holding `uwgen.yaml`.
- Interface folders are positional `DIR` arguments (an interface package, or a folder of
  packages), in every command that reads them.
- Every option with a default shows it in `--help` (HelpFormatter).
- An old spelling of an option still works and prints a note with the new one
  (`old_spelling`).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from uwgen import safefile

MANIFEST_NAME = "uwgen.yaml"   # the same as uwgen.manifest.loader.MANIFEST_NAME (not imported: no yaml here)
MANIFEST_HELP = f"the manifest: a file, or a folder holding {MANIFEST_NAME}"


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions as written; every option's default in its help, unless the help says it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if ("default" in text.lower() or default is None or default is argparse.SUPPRESS
                or isinstance(default, bool) or default == [] or not action.option_strings):
            return text
        shown = " ".join(map(str, default)) if isinstance(default, (list, tuple)) else "%(default)s"
        return f"{text} (default: {shown})"


def manifest_path(text: str) -> Path:
    """argparse type of -m: a folder stands for its uwgen.yaml. A name that cannot lead to a
    manifest (a symlink loop, a name too long, a device, a FIFO) is a usage error here,
    before any command resolves or reads it; a missing file is left to the command."""
    path = Path(text)
    try:
        is_dir = path.is_dir()
    except (OSError, ValueError):
        is_dir = False
    if is_dir:
        candidate = path / MANIFEST_NAME
        if safefile.problem(candidate, "manifest") is None and not candidate.is_file():
            raise argparse.ArgumentTypeError(f"{path} is a folder without a {MANIFEST_NAME}")
        path = candidate
    why = safefile.problem(path, "manifest")
    if why is not None:
        raise argparse.ArgumentTypeError(why)
    return path


def add_manifest(parser: argparse.ArgumentParser, required: bool = False, help: str | None = None) -> None:
    parser.add_argument("-m", "--manifest", type=manifest_path, required=required, metavar="MANIFEST",
                        help=f"{MANIFEST_HELP}" + (f"; {help}" if help else ""))


def add_folders(parser: argparse.ArgumentParser, help: str, required: bool = False) -> None:
    parser.add_argument("folders", nargs="+" if required else "*", type=Path, metavar="DIR",
                        default=[], help=help)


def old_spelling(parser: argparse.ArgumentParser, old: str | tuple[str, ...], new: str, dest: str,
                 command: str, append: bool = False, **kwargs) -> None:
    """Accept `old` for the option now spelled `new` (stored in `dest`, appended to a list
    with `append`), with a note on stderr; not listed in --help."""
    class _Old(argparse.Action):
        def __call__(self, p, namespace, values, option_string=None):
            print(f"uwgen {command}: note: {option_string} is now {new}; the old spelling still works",
                  file=sys.stderr)
            if append:
                values = [*(getattr(namespace, dest, None) or []), values]
            setattr(namespace, dest, values)

    names = (old,) if isinstance(old, str) else old
    parser.add_argument(*names, dest=dest, action=_Old, help=argparse.SUPPRESS, **kwargs)


def all_parsers(parser: argparse.ArgumentParser):
    """`parser` and every sub-command parser under it."""
    yield parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):
                yield from all_parsers(sub)
