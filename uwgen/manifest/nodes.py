"""Reading YAML while keeping where every value came from.

`yaml.safe_load` forgets line numbers; the manifest needs them for every error. This
module composes the YAML into nodes (which carry their marks) and offers typed reads
that raise `ManifestError` at the offending node's 1-based `line:column`.
"""
from __future__ import annotations

import difflib
import math
import re
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


# YAML 1.1 (PyYAML) and YAML 1.2 read these plain scalars differently, and neither reading is
# what a person writing a manifest expects: `1:30` is 90 in base 60 (1.2: a string), `1_000`
# is 1000 (1.2: a string), `017` is octal 15 (1.2: 17), `0b11` is 3 (1.2: a string), `+5` is
# signed where no other number is, and `0o17`, octal in 1.2, is a string in 1.1. A number in
# a manifest is plain decimal (or 0x hexadecimal, the same in both); these are refused where
# they stand, with the number to write instead.
_OCTAL_11 = re.compile(r"[-+]?0[0-7_]+")
_OCTAL_12 = re.compile(r"[-+]?0o[0-7]+")


def yaml11_surprise(text: str, value) -> str | None:
    """Why the plain scalar `text`, read as `value`, must be written otherwise, or None."""
    plain = _shorten(text)
    number = str(value) if isinstance(value, int) else repr(value)
    if isinstance(value, str):
        if _OCTAL_12.fullmatch(text):
            return (f"{plain} is octal in YAML 1.2 but text in YAML 1.1, which uwgen reads: "
                    f"write {int(text.replace('0o', ''), 8)}")
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    if ":" in text:
        return (f"{plain} is a base-60 number in YAML 1.1 ({number}) and text in YAML 1.2: "
                f"write {number} (or quote it, for text)")
    if "_" in text:
        return (f"{plain} has '_', which YAML 1.1 drops and YAML 1.2 does not: write {number} "
                "(or quote it, for text)")
    if text.lower().lstrip("+-").startswith("0b"):
        return f"{plain} is binary in YAML 1.1 only: write {number}"
    if isinstance(value, int) and _OCTAL_11.fullmatch(text):
        return (f"{plain} is octal in YAML 1.1 ({value}) and decimal in YAML 1.2 "
                f"({int(text)}): write {value} or {int(text)} without the leading 0")
    if text.startswith("+"):
        return f"write {text[1:]} without the '+' sign"
    return None


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
        # With a collector (the manifest builder's), an unknown, repeated or unreadable key
        # is collected and skipped instead of ending the read: the rest of the mapping is
        # still checked, so every mistake of a manifest comes in one pass.
        self.collect = None
        # (line, column) of the mappings a key was refused in: an error located at one of them
        # afterwards ("says nothing", "missing the required key") is a consequence, not news.
        self.damaged: set[tuple[int, int]] = set()

    def _refuse(self, error: ManifestError, mapping: yaml.Node) -> None:
        if self.collect is None:
            raise error
        self.damaged.add((mapping.start_mark.line + 1, mapping.start_mark.column + 1))
        self.collect.add(error)

    def consequence(self, error: Exception) -> bool:
        """Whether `error` is located at a mapping whose own key was refused already."""
        where = getattr(error, "where", None)
        return where is not None and (where.line, where.column) in self.damaged

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
            try:
                key = self._key(key_node, what)
            except ManifestError as error:
                self._refuse(error, node)
                continue
            if key in entries:
                first = self.where(entries[key][0])
                self._refuse(self.error(key_node, f"duplicate key '{key}' in {what} (first at line {first.line})"), node)
            elif known and key not in known:
                self._refuse(self.error(key_node, self.unknown_key_message(key, what, known)), node)
            else:
                entries[key] = (key_node, value_node)
        return entries

    def open_mapping(self, node: yaml.Node, what: str) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        """A mapping whose keys are names chosen by the user (e.g. sides), or checked later."""
        return self.mapping(node, what, ())

    def check_keys(self, entries: dict[str, tuple[yaml.Node, yaml.Node]], what: str, known: tuple[str, ...]) -> None:
        """Refuse keys of an `open_mapping` that are not in `known`, in file order."""
        for key, (key_node, _) in list(entries.items()):
            if key not in known:
                self._refuse(self.error(key_node, self.unknown_key_message(key, what, known)),
                             entries[key][1])   # no mapping node here: its value stands for it
                del entries[key]

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

    def value(self, node: yaml.Node, what: str | None = None):
        """The Python value of a scalar node (YAML's own typing: 4 is int, 4.0 float, null None);
        a number spelled so that YAML 1.1 and 1.2 disagree is an error (`yaml11_surprise`),
        naming `what` when given."""
        if not isinstance(node, yaml.ScalarNode):
            return node
        try:
            value = self._constructor.construct_object(node, deep=True)
        except (ConstructorError, ValueError) as exc:
            raise self.error(node, f"cannot read value: {exc}") from None
        if isinstance(value, int) and not isinstance(value, bool) and not -LARGEST_INT <= value <= LARGEST_INT:
            raise self.error(node, f"the integer {_shorten(node.value)} is out of range: no value in "
                                   f"a manifest is beyond 64 bits (±{LARGEST_INT})")
        if node.style is None and not isinstance(value, str):
            surprise = yaml11_surprise(node.value, value)
            if surprise:
                raise self.error(node, f"{what}: {surprise}" if what else surprise)
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

    def expected_number(self, node: yaml.Node, value, what: str) -> None:
        """A plain `0o17` where a number is expected: say why it is text, not only that it is."""
        if isinstance(value, str) and isinstance(node, yaml.ScalarNode) and node.style is None:
            surprise = yaml11_surprise(node.value, value)
            if surprise:
                raise self.error(node, f"{what}: {surprise}")

    def integer(self, node: yaml.Node, what: str, lo: int | None = None, hi: int | None = None) -> int:
        value = self.value(node, what)
        self.expected_number(node, value, what)
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
        value = self.value(node, what)
        self.expected_number(node, value, what)
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
        if isinstance(node, yaml.ScalarNode) and self.value(node, what) is None:
            return None
        value = self.value(node, what)
        if isinstance(value, (int, float)) and not isinstance(value, bool) and value <= 0:
            raise self.error(node, f"{what} must be > 0 (or null for no limit), got {value}")
        return self.number(node, what)

    def choice(self, node: yaml.Node, what: str, options: tuple[str, ...]) -> str:
        value = self.value(node)
        if not isinstance(value, str) or value not in options:
            shown = node.value if isinstance(node, yaml.ScalarNode) else self.describe(node)
            raise self.error(node, f"{what} must be one of {', '.join(options)}; got {shown!r}")
        return value
