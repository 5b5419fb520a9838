"""Where interfaces are found: the index of `InterfaceLibrary` (uwgen/idl/loader.py).

Given folders come first, each a parent of packages or a package folder itself; then each
install prefix's `share/<package>/{msg,srv,action}/`. A package found in a given folder hides
the installed package of the same name; among prefixes the first that has a package provides
it. Indexing lists folders only: nothing is parsed here.
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

from uwgen.idl import names
from uwgen.idl.model import DefinitionError, SourceRef

KINDS = (("msg", ".msg"), ("srv", ".srv"), ("action", ".action"))


@dataclass(frozen=True)
class Entry:
    full_name: str
    package: str
    path: Path
    local: bool


def default_prefixes() -> list[Path]:
    """Install prefixes searched for `share/<package>/msg|srv`: sys.prefix, then AMENT_PREFIX_PATH."""
    prefixes = [Path(sys.prefix)]
    for item in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if item:
            prefixes.append(Path(item))
    return prefixes


def index_interfaces(folders: list[Path], prefixes: list[Path]) -> dict[str, Entry]:
    """Full name -> where its file is, for the given folders and then the installed prefixes."""
    index: dict[str, Entry] = {}
    _index_installed(index, prefixes, _index_folders(index, folders))
    return index


def _index_folders(index: dict[str, Entry], folders: list[Path]) -> set[str]:
    seen_real: set[Path] = set()
    packages: set[str] = set()
    for folder in folders:
        try:
            is_dir = folder.is_dir()
        except OSError as exc:          # a name too long for the system, say
            raise DefinitionError(SourceRef(folder, 1, 1),
                                  f"interface folder cannot be looked at: {exc.strerror or exc}") from None
        if not is_dir:
            raise DefinitionError(SourceRef(folder, 1, 1), "interface folder does not exist or is not a folder")
        found = False
        for package_dir in _package_dirs(folder):
            real = package_dir.resolve()
            if real in seen_real:
                found = True
                continue
            seen_real.add(real)
            package = package_dir.name
            if not names.is_package_name(package):
                raise DefinitionError(
                    SourceRef(package_dir, 1, 1),
                    f"'{package}' is not a valid ROS package name (lower case letters, digits, '_')",
                )
            for entry in _package_entries(package, package_dir, local=True):
                previous = index.get(entry.full_name)
                if previous is not None:
                    raise DefinitionError(
                        SourceRef(entry.path, 1, 1),
                        f"{entry.full_name} is defined twice: also in {previous.path}",
                    )
                index[entry.full_name] = entry
                found = True
            packages.add(package)
        if not found:
            raise DefinitionError(
                SourceRef(folder, 1, 1),
                "no interfaces found: expected <package>/msg/*.msg, <package>/srv/*.srv or "
                "<package>/action/*.action (or a package folder with msg/, srv/ or action/)",
            )
    return packages

def _package_dirs(folder: Path) -> list[Path]:
    def has_kinds(d: Path) -> bool:
        return any((d / kind).is_dir() for kind, _ in KINDS)
    if has_kinds(folder):
        return [folder]
    return sorted(child for child in folder.iterdir() if child.is_dir() and has_kinds(child))

def _package_entries(package: str, package_dir: Path, local: bool) -> list[Entry]:
    entries = []
    for kind, suffix in KINDS:
        sub = package_dir / kind
        if not sub.is_dir():
            continue
        for path in sorted(sub.iterdir()):
            if path.suffix == suffix and path.is_file():
                entries.append(Entry(f"{package}/{kind}/{path.stem}", package, path, local))
    return entries

def _index_installed(index: dict[str, Entry], prefixes: list[Path], hidden: set[str]) -> None:
    provided: set[str] = set(hidden)
    for prefix in prefixes:
        share = prefix / "share"
        try:
            children = sorted(os.scandir(share), key=lambda e: e.name)
        except OSError:
            continue
        for child in children:
            if child.name in provided or not child.is_dir():
                continue
            package_dir = Path(child.path)
            entries = _package_entries(child.name, package_dir, local=False)
            if not entries:
                continue
            provided.add(child.name)
            for entry in entries:
                index[entry.full_name] = entry
