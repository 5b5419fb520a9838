"""Reading YAML while keeping where every value came from.

`yaml.safe_load` forgets line numbers; the manifest needs them for every error. This
module composes the YAML into nodes (which carry their marks) and offers typed reads
that raise `ManifestError` at the offending node's 1-based `line:column`.
"""
from __future__ import annotations

import difflib
import math
from pathlib import Path

import yaml
from yaml.constructor import ConstructorError, SafeConstructor

from uwgen import safefile, yamltext
from uwgen.idl.model import SourceRef


# Integers a manifest may hold (any field type's range: int64, uint64), and the range of the
# numbers that become times and rates (1e9 s is 31 years; 1e-6 s a microsecond).
LARGEST_INT = 2 ** 64 - 1
MAX_NUMBER = 1e9
MIN_POSITIVE = 1e-6


def _shorten(text: str, keep: int = 24) -> str:
    """A value as the file spells it, cut short when long (a 400-digit number)."""
    return text if len(text) <= keep else f"{text[:keep]}... ({len(text)} characters)"


class ManifestError(Exception):
    """A problem in a manifest; str() is `file:line:column: message`."""

    def __init__(self, where: SourceRef | None, message: str):
        self.where = where
        self.message = message
        super().__init__(f"{where}: {message}" if where else message)


def compose(path: Path) -> yaml.Node | None:
    """The YAML document of `path` as a node tree (None for an empty document)."""
    try:
        text = yamltext.read(path, "manifest")
    except safefile.UnreadableFile as exc:
        if exc.line:
            raise ManifestError(SourceRef(path, exc.line, exc.column), exc.reason) from None
        raise ManifestError(None, str(exc)) from None
    try:
        return yaml.compose(text, Loader=yamltext.Loader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = SourceRef(path, mark.line + 1, mark.column + 1) if mark else SourceRef(path, 1, 1)
        problem = exc.problem or exc.context or "invalid YAML"
        raise ManifestError(where, f"YAML syntax error: {problem}") from None
    except yaml.YAMLError as exc:
        raise ManifestError(SourceRef(path, 1, 1), f"YAML error: {exc}") from None


class Reader:
    """Typed access to the nodes of one manifest file."""

    def __init__(self, path: Path):
        self.path = path
        self._constructor = SafeConstructor()

    def where(self, node: yaml.Node) -> SourceRef:
        mark = node.start_mark
        return SourceRef(self.path, mark.line + 1, mark.column + 1)

    def error(self, node: yaml.Node, message: str) -> ManifestError:
        return ManifestError(self.where(node), message)

    # -- containers ------------------------------------------------------------------

    def mapping(self, node: yaml.Node, what: str, known: tuple[str, ...]) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        """A mapping's entries as {key: (key node, value node)}; unknown or repeated keys are errors."""
        if not isinstance(node, yaml.MappingNode):
            raise self.error(node, f"{what} must be a mapping, got {self.describe(node)}")
        entries: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for key_node, value_node in node.value:
            key = self._key(key_node, what)
            if key in entries:
                first = self.where(entries[key][0])
                raise self.error(key_node, f"duplicate key '{key}' in {what} (first at line {first.line})")
            if known and key not in known:
                raise self.error(key_node, self.unknown_key_message(key, what, known))
            entries[key] = (key_node, value_node)
        return entries

    def open_mapping(self, node: yaml.Node, what: str) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        """A mapping whose keys are names chosen by the user (e.g. sides), or checked later."""
        return self.mapping(node, what, ())

    def check_keys(self, entries: dict[str, tuple[yaml.Node, yaml.Node]], what: str, known: tuple[str, ...]) -> None:
        """Refuse keys of an `open_mapping` that are not in `known`, in file order."""
        for key, (key_node, _) in entries.items():
            if key not in known:
                raise self.error(key_node, self.unknown_key_message(key, what, known))

    def _key(self, key_node: yaml.Node, what: str) -> str:
        if not isinstance(key_node, yaml.ScalarNode):
            raise self.error(key_node, f"keys of {what} must be plain names")
        key = self.value(key_node)
        if not isinstance(key, str):
            raise self.error(key_node, f"keys of {what} must be names, got {self.describe(key_node)}")
        return key

    @staticmethod
    def unknown_key_message(key: str, what: str, known: tuple[str, ...]) -> str:
        close = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
        if close:
            return f"unknown key '{key}' in {what}; did you mean '{close[0]}'?"
        return f"unknown key '{key}' in {what}; known keys: {', '.join(known)}"

    def sequence(self, node: yaml.Node, what: str) -> list[yaml.Node]:
        if isinstance(node, yaml.ScalarNode) and self.value(node) is None:
            return []
        if not isinstance(node, yaml.SequenceNode):
            raise self.error(node, f"{what} must be a list, got {self.describe(node)}")
        return list(node.value)

    def require(self, entries: dict, key: str, owner: yaml.Node, what: str) -> yaml.Node:
        if key not in entries:
            raise self.error(owner, f"{what} is missing the required key '{key}'")
        return entries[key][1]

    # -- scalars ---------------------------------------------------------------------

    def value(self, node: yaml.Node):
        """The Python value of a scalar node (YAML's own typing: 4 is int, 4.0 float, null None)."""
        if not isinstance(node, yaml.ScalarNode):
            return node
        try:
            value = self._constructor.construct_object(node, deep=True)
        except (ConstructorError, ValueError) as exc:
            raise self.error(node, f"cannot read value: {exc}") from None
        if isinstance(value, int) and not isinstance(value, bool) and not -LARGEST_INT <= value <= LARGEST_INT:
            raise self.error(node, f"the integer {_shorten(node.value)} is out of range: no value in "
                                   f"a manifest is beyond 64 bits (±{LARGEST_INT})")
        return value

    def describe(self, node: yaml.Node) -> str:
        if isinstance(node, yaml.MappingNode):
            return "a mapping"
        if isinstance(node, yaml.SequenceNode):
            return "a list"
        value = self.value(node)
        if value is None:
            return "nothing (null)"
        kinds = {bool: "a boolean", int: "an integer", float: "a number", str: "a string"}
        return f"{kinds.get(type(value), type(value).__name__)} ({node.value!r})"

    def string(self, node: yaml.Node, what: str) -> str:
        value = self.value(node)
        if not isinstance(value, str):   # value() of a mapping or list is the node itself
            raise self.error(node, f"{what} must be a string, got {self.describe(node)}")
        return value

    def integer(self, node: yaml.Node, what: str, lo: int | None = None, hi: int | None = None) -> int:
        value = self.value(node)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(node, f"{what} must be an integer, got {self.describe(node)}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            if hi is None:
                raise self.error(node, f"{what} must be >= {lo}, got {value}")
            raise self.error(node, f"{what} must be in {lo}..{hi}, got {value}")
        return value

    def boolean(self, node: yaml.Node, what: str) -> bool:
        value = self.value(node)
        if not isinstance(value, bool):
            raise self.error(node, f"{what} must be true or false, got {self.describe(node)}")
        return value

    def number(self, node: yaml.Node, what: str, positive: bool = True) -> float:
        """A finite number within ±MAX_NUMBER; with `positive`, at least MIN_POSITIVE (rates,
        periods, timeouts and ttls: anything else overflows the timers it ends up in)."""
        value = self.value(node)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(node, f"{what} must be a number, got {self.describe(node)}")
        if not math.isfinite(value):
            raise self.error(node, f"{what} must be a finite number, got {value}")
        if positive and value <= 0:
            raise self.error(node, f"{what} must be > 0, got {value}")
        if abs(value) > MAX_NUMBER or (positive and value < MIN_POSITIVE):
            span = f"{MIN_POSITIVE:g}..{MAX_NUMBER:g}" if positive else f"-{MAX_NUMBER:g}..{MAX_NUMBER:g}"
            raise self.error(node, f"{what} must be in {span}, got {_shorten(node.value)}")
        return float(value)

    def optional_number(self, node: yaml.Node, what: str) -> float | None:
        """A positive number, or null meaning 'no limit'."""
        if isinstance(node, yaml.ScalarNode) and self.value(node) is None:
            return None
        value = self.value(node)
        if isinstance(value, (int, float)) and not isinstance(value, bool) and value <= 0:
            raise self.error(node, f"{what} must be > 0 (or null for no limit), got {value}")
        return self.number(node, what)

    def choice(self, node: yaml.Node, what: str, options: tuple[str, ...]) -> str:
        value = self.value(node)
        if not isinstance(value, str) or value not in options:
            shown = node.value if isinstance(node, yaml.ScalarNode) else self.describe(node)
            raise self.error(node, f"{what} must be one of {', '.join(options)}; got {shown!r}")
        return value
