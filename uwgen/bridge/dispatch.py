"""Route each payload received from the link by its (kind, id), read once from its header.

Parts register what they take (`route`) and what they themselves send (`sends`). A
payload that fits no route is never dropped silently; it is counted in BridgeCounters as

- `bad_header`: no readable kind and id at its start;
- `wrong_direction`: the (kind, id) is one this side sends (e.g. the topic it publishes
  came back from the link);
- `bad_kind`: the id is bridged here but not with this kind (a topic id with kind 2);
- `unknown_id`: no entry of this side has the id (or it is not bridged here);
- `overheard` (not a drop): the id is another fleet vehicle's entry (`overhears`), heard on
  the shared channel.
"""
from __future__ import annotations

from typing import Callable

from uwgen.bridge.counters import BridgeCounters
from uwgen.runtime.wire.codec import DecodeError, peek_header

Handler = Callable[[int, bytes], None]   # (id, whole payload)


class Dispatcher:
    def __init__(self, counters: BridgeCounters):
        self.counters = counters
        self._routes: dict[tuple[int, int], Handler] = {}
        self._sent: set[tuple[int, int]] = set()
        self._known: set[int] = set()
        self._screens: list[Callable[[int], bool]] = []
        self._overheard: set[int] = set()

    def route(self, kind: int, ident: int, handler: Handler) -> None:
        """Payloads of (kind, ident) go to handler(ident, payload)."""
        key = (kind, ident)
        if key in self._routes:
            raise ValueError(f"kind {kind} id {ident} is routed twice")
        self._routes[key] = handler
        self._known.add(ident)

    def sends(self, kind: int, ident: int) -> None:
        """This side sends (kind, ident): receiving it is a wrong direction, not unknown."""
        self._sent.add((kind, ident))
        self._known.add(ident)

    def overhears(self, ident: int) -> None:
        """`ident` is another side's entry (a fleet peer's): counted `overheard`, not unknown."""
        self._overheard.add(ident)

    def screen(self, admit: Callable[[int], bool]) -> None:
        """Payloads of an id for which admit(id) is False are dropped before routing;
        `admit` counts what it refuses (e.g. schema.SchemaGuard.accept)."""
        self._screens.append(admit)

    def dispatch(self, payload: bytes) -> None:
        try:
            key = peek_header(payload)
        except DecodeError:
            self.counters.bad_header += 1
            return
        for admit in self._screens:
            if not admit(key[1]):
                return
        handler = self._routes.get(key)
        if handler is not None:
            handler(key[1], payload)
        elif key in self._sent:
            self.counters.wrong_direction += 1
        elif key[1] in self._known:
            self.counters.bad_kind += 1
        elif key[1] in self._overheard:
            self.counters.overheard += 1
        else:
            self.counters.unknown_id += 1
