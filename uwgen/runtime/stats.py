"""Named counters for the link layer, and a logger helper that speaks once per state change.

Every drop in the link layer is counted by reason; `stats()` of each component returns plain dicts
of ints so that `Link.stats()` is JSON-able and a status topic can publish it as is.
"""
from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator, Mapping


class Counters(Mapping[str, int]):
    """A fixed set of named integer counters that only grow.

    The names are fixed at construction so that a typo in `inc("overflw")` fails loudly instead of
    silently starting a new counter that nobody reads.
    """

    __slots__ = ("_c",)

    def __init__(self, names: Iterable[str]):
        self._c: dict[str, int] = dict.fromkeys(names, 0)

    def inc(self, name: str, n: int = 1) -> int:
        if name not in self._c:
            raise KeyError(f"unknown counter {name!r} (known: {', '.join(self._c)})")
        self._c[name] += n
        return self._c[name]

    def __getitem__(self, name: str) -> int:
        return self._c[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._c)

    def __len__(self) -> int:
        return len(self._c)

    def as_dict(self) -> dict[str, int]:
        return dict(self._c)

    def __repr__(self) -> str:
        return f"Counters({self._c})"


def log_count(logger: logging.Logger, level: int, count: int, message: str, *args: object,
              exc_info: bool = False) -> None:
    """Log a repeated event on its 1st, 10th, 100th, ... occurrence only (never once per message).

    `message` gets ` (N so far)` appended after the first occurrence. `exc_info=True` adds the
    exception being handled, as `logger.exception` would.
    """
    if count == 1:
        logger.log(level, message, *args, exc_info=exc_info)
    elif _is_power_of_ten(count):
        logger.log(level, message + " (%d so far)", *args, count, exc_info=exc_info)


def _is_power_of_ten(n: int) -> bool:
    while n >= 10 and n % 10 == 0:
        n //= 10
    return n == 1
