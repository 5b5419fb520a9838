"""YAML as uwgen reads it: PyYAML's safe loader, with nesting depth bounded.

PyYAML composes and constructs nested collections by recursion, so a document nested a few
thousand levels deep (`[[[[...`) ends in RecursionError instead of an error message. Every
YAML file uwgen reads (manifests, scenarios, hints) goes through `Loader`, which refuses
nesting deeper than MAX_DEPTH with an ordinary `yaml.MarkedYAMLError` at the line and
column where the too-deep collection starts; the callers already turn those into located
errors. `read` reads such a file safely (a regular file of at most MAX_BYTES).

    node = yaml.compose(read(path, "manifest"), Loader=Loader)   # or yaml.load(...)
"""
from __future__ import annotations

from pathlib import Path

import yaml
from yaml.composer import ComposerError

from uwgen import safefile

# A manifest is at most about 6 levels deep (topics > entry > fields > path > options);
# anything past this is not a configuration but an attack or an accident.
MAX_DEPTH = 64
# The most bytes of one YAML file uwgen reads: the demo's manifest is 6 KiB; a file past
# this (or /dev/zero behind a manifest's name) is refused before it is read.
MAX_BYTES = 1024 ** 2


class Loader(yaml.SafeLoader):
    """yaml.SafeLoader that refuses collections nested deeper than MAX_DEPTH."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        if self._depth >= MAX_DEPTH:
            mark = self.peek_event().start_mark
            raise ComposerError(None, None,
                                f"nested more than {MAX_DEPTH} levels deep (uwgen reads at most "
                                f"{MAX_DEPTH})", mark)
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def safe_load(text: str):
    """yaml.safe_load with the depth bound (raises yaml.YAMLError subclasses only)."""
    return yaml.load(text, Loader=Loader)


def read(path: Path | str, what: str) -> str:
    """The text of the YAML file `path` (regular, at most MAX_BYTES, UTF-8), read with
    `uwgen.safefile`; safefile.UnreadableFile if not."""
    return safefile.read_text(path, what, MAX_BYTES)
