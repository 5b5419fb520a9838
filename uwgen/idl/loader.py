"""The interface library: every `.msg`/`.srv`/`.action` uwgen can see, parsed on demand.

Interfaces come from two places:

- folders given explicitly (e.g. `msg_samples/`), each either a parent of packages
  (`<folder>/<package>/msg/*.msg`, `<folder>/<package>/srv/*.srv`,
  `<folder>/<package>/action/*.action`) or a package folder itself (one that has `msg/`,
  `srv/` or `action/`);
- installed ROS packages: `<prefix>/share/<package>/{msg,srv,action}/` for the environment's
  own prefix (`sys.prefix`, where the ROS wheels install) and then every entry of
  `AMENT_PREFIX_PATH`, in order. The first prefix that has a package provides it.

A package found in a given folder hides the installed package of the same name entirely
(a local copy replaces the installed one; mixing files of two versions of a package
would be wrong). `.idl` files are ignored. An action's goal, result and feedback are
messages named `pkg/action/Name_Goal`, `_Result` and `_Feedback`.

Building the index only lists folders; files are parsed the first time they are asked
for and cached, so naming one type costs one parse plus its dependencies.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Sequence

from uwgen.idl import names
from uwgen.idl.index import KINDS, Entry, default_prefixes, index_interfaces
from uwgen.idl.model import (ACTION_PARTS, ActionDef, DefinitionError, InterfaceDef, MessageDef,
                             ServiceDef)
from uwgen.idl.parser import parse_file


class UnknownInterface(DefinitionError, KeyError):
    """`InterfaceLibrary.get` was asked for a name it does not know."""

    def __str__(self) -> str:  # KeyError would quote the message
        return DefinitionError.__str__(self)


class InterfaceLibrary:
    """Every interface known from the given folders and (optionally) installed packages."""

    def __init__(
        self,
        folders: Iterable[Path | str] = (),
        installed: bool = True,
        prefixes: Sequence[Path | str] | None = None,
    ):
        self.folders = [Path(f) for f in folders]
        self.prefixes = [Path(p) for p in (default_prefixes() if prefixes is None else prefixes)] if installed else []
        self._parsed: dict[Path, InterfaceDef] = {}
        self._checked: set[str] = set()
        self._index: dict[str, Entry] = index_interfaces(self.folders, self.prefixes)

    # -- names -----------------------------------------------------------------------

    def local_names(self) -> list[str]:
        """Full names defined in the given folders (not installed ones), sorted."""
        return sorted(n for n, e in self._index.items() if e.local)

    def all_names(self) -> list[str]:
        """Every interface known (folders and installed), sorted."""
        return sorted(self._index)

    def search_paths(self) -> list[Path]:
        """Where interfaces are looked for, for error messages: the folders, then each prefix's share/."""
        return [*self.folders, *(p / "share" for p in self.prefixes)]

    def looked_in(self) -> str:
        """`search_paths()` as one phrase for the '(looked in: ...)' of error messages."""
        return ", ".join(str(p) for p in self.search_paths()) or "no folders and no installed packages"

    def normalize(self, name: str) -> str | None:
        """The full name (`pkg/msg/Name`, `pkg/srv/Name`, `pkg/srv/Name_Request`,
        `pkg/action/Name`, `pkg/action/Name_Goal`) for `name`, if known.

        `pkg/Name` means the message if there is one, else the service, else the action.
        """
        resolved = self._resolve(name)
        return None if resolved is None else resolved[0]

    def _resolve(self, name: str) -> tuple[str, Entry, str | None] | None:
        """(full name, entry, part) for any spelling `normalize` accepts; see `_lookup`."""
        parts = name.split("/")
        if len(parts) == 2:
            candidates = [f"{parts[0]}/{kind}/{parts[1]}" for kind, _ in KINDS]
        elif len(parts) == 3:
            candidates = [name]
        else:
            return None
        for full in candidates:
            found = self._lookup(full)
            if found is not None:
                return full, *found
        return None

    def _lookup(self, full: str) -> tuple[Entry, str | None] | None:
        """(entry, part) for a full name; part is 'request'/'response' for a service's
        message, 'goal'/'result'/'feedback' for an action's."""
        entry = self._index.get(full)
        if entry is not None:
            return entry, None
        for ns, suffixes in (("srv", ("Request", "Response")), ("action", ACTION_PARTS)):
            pkg, _, rest = full.partition(f"/{ns}/")
            if not rest:
                continue
            for suffix in suffixes:
                if rest.endswith(f"_{suffix}"):
                    entry = self._index.get(f"{pkg}/{ns}/{rest[: -len(suffix) - 1]}")
                    if entry is not None:
                        return entry, suffix.lower()
        return None

    def __contains__(self, name: str) -> bool:
        return self.normalize(name) is not None

    def source_of(self, name: str) -> Path | None:
        """The file that defines `name`, if known."""
        resolved = self._resolve(name)
        return None if resolved is None else resolved[1].path

    # -- definitions -----------------------------------------------------------------

    def find(self, name: str) -> InterfaceDef | None:
        """The definition of `name` (any spelling `normalize` accepts), or None if unknown.

        Raises DefinitionError if the file is broken or uses a type that does not exist.
        """
        resolved = self._resolve(name)
        if resolved is None:
            return None
        _, entry, part = resolved
        definition = self._parse(entry)
        self._check(definition)
        if part is not None:
            return getattr(definition, part)
        return definition

    def get(self, name: str) -> InterfaceDef:
        """Like `find`, but an unknown name raises UnknownInterface (a DefinitionError and KeyError)."""
        definition = self.find(name)
        if definition is None:
            raise UnknownInterface(None, self.describe_unknown(name))
        return definition

    def describe_unknown(self, name: str) -> str:
        """Why `name` is unknown and where it was looked for (for error messages)."""
        if names.split_type_name(name) is None:
            return f"'{name}' is not an interface name: expected pkg/msg/Name, pkg/srv/Name, pkg/action/Name or pkg/Name"
        return f"unknown interface '{name}' (looked in: {self.looked_in()})"

    def _parse(self, entry: Entry) -> InterfaceDef:
        definition = self._parsed.get(entry.path)
        if definition is None:
            definition = parse_file(entry.path, entry.package)
            self._parsed[entry.path] = definition
        return definition

    def _check(self, definition: InterfaceDef) -> None:
        """Every nested type a definition names must exist and be a message."""
        if definition.full_name in self._checked:
            return
        for message in parts_of(definition):
            for f in message.fields:
                if f.type.is_primitive:
                    continue
                base = f.type.base
                entry = self._index.get(base)
                if entry is None:
                    raise DefinitionError(f.where, self._unresolved_message(base, message))
        self._checked.add(definition.full_name)

    def _unresolved_message(self, base: str, message: MessageDef) -> str:
        pkg, _, name = base.split("/")
        if self.normalize(f"{pkg}/srv/{name}") is not None:
            return f"'{pkg}/srv/{name}' is a service; a field needs a message type"
        text = f"unknown type '{base}'"
        if name == "Header" and pkg != "std_msgs" and "std_msgs/msg/Header" in self._index:
            text += " (ROS 2 does not resolve a bare 'Header' to std_msgs: write std_msgs/Header)"
        return f"{text} used by {message.full_name} (looked in: {self.looked_in()})"

    def closure(self, names_: Iterable[str]) -> list[MessageDef]:
        """The messages these interfaces use, dependencies first, each once.

        Services contribute their request and response (and what those use); the named
        messages themselves are included. A message that contains itself, directly or
        through others, is a DefinitionError at the field that closes the loop.
        """
        order: list[MessageDef] = []
        done: set[str] = set()
        for name in names_:
            for root in parts_of(self.get(name)):
                self._visit(root, order, done, [])
        return order

    def _visit(self, message: MessageDef, order: list[MessageDef], done: set[str], stack: list[str]) -> None:
        if message.full_name in done:
            return
        stack.append(message.full_name)
        for f in message.fields:
            if f.type.is_primitive:
                continue
            if f.type.base in stack:
                loop = " -> ".join([*stack[stack.index(f.type.base):], f.type.base])
                raise DefinitionError(f.where, f"recursive message type: {loop} (a message cannot contain itself)")
            nested = self.get(f.type.base)
            self._visit(nested, order, done, stack)
        stack.pop()
        done.add(message.full_name)
        order.append(message)


def parts_of(definition: InterfaceDef) -> list[MessageDef]:
    """The messages of an interface: itself, a service's request and response, or an
    action's goal, result and feedback."""
    if isinstance(definition, ServiceDef):
        return [definition.request, definition.response]
    if isinstance(definition, ActionDef):
        return definition.parts
    return [definition]
