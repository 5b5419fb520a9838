"""Several problems at once: a build reports every error it finds (up to a limit).

    errors = Collector()
    for entry in entries:
        with errors.attempt(ManifestError, DefinitionError):
            check(entry)
    errors.raise_if_any()     # nothing, the one error itself, or ErrorList of them all

Each collected error keeps its own `file:line:column` message; `ErrorList` carries them
in order (the first MAX_ERRORS; `more` counts the rest).
"""
from __future__ import annotations

from contextlib import contextmanager

MAX_ERRORS = 20


class ErrorList(Exception):
    """More than one independent problem; str() is one located message per line."""

    def __init__(self, errors: list[Exception], more: int = 0):
        self.errors = list(errors)
        self.more = more
        super().__init__("\n".join(str(e) for e in self.errors))

    def summary(self) -> str:
        total = len(self.errors) + self.more
        if self.more:
            return f"{total} errors (the first {len(self.errors)} shown)"
        return f"{total} errors"


class Collector:
    """Collects errors up to `limit`; counts the ones beyond it."""

    def __init__(self, limit: int = MAX_ERRORS):
        self.limit = limit
        self.errors: list[Exception] = []
        self.more = 0

    def add(self, error: Exception) -> None:
        for e in getattr(error, "errors", None) or [error]:
            if any(str(e) == str(seen) for seen in self.errors):
                continue   # one broken file named twice (by the folder and by the manifest)
            if len(self.errors) < self.limit:
                self.errors.append(e)
            else:
                self.more += 1
        self.more += getattr(error, "more", 0)

    @contextmanager
    def attempt(self, *kinds: type[Exception]):
        try:
            yield
        except kinds as exc:
            self.add(exc)

    @property
    def count(self) -> int:
        """Errors found so far, kept or only counted."""
        return len(self.errors) + self.more

    def __bool__(self) -> bool:
        return bool(self.errors)

    def raise_if_any(self, combined: type[ErrorList] = ErrorList) -> None:
        if len(self.errors) == 1 and not self.more:
            raise self.errors[0]
        if self.errors:
            raise combined(self.errors, self.more)
