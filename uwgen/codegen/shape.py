"""Refuse, at build time, message types no codec can be generated for.

- A recursive type (one that contains itself directly, through other types, or through
  an array of itself) has no finite wire form that uwgen's flattened layout can carry;
  ROS 2 refuses it too. It is a DefinitionError at the field that closes the loop.
- Nesting deeper than MAX_NESTING levels is refused at the field that crosses the limit.
  A message with only primitive fields is 1 level deep; each nested message field, single
  or array, adds one. The deepest standard ROS message (e.g. nav_msgs/Odometry) is 4
  levels deep, so the limit is far above any real interface, and far below what Python
  takes: the generator and the generated code recurse about once per level (Python's
  limit is 1000 frames) and the emitter keeps every generated expression well under the
  parser's 200 nested parentheses (uwgen.codegen.emit_decode.NEST_CHUNK).

Both checks are iterative, so even a pathological definition gets the located error,
never a RecursionError.
"""
from __future__ import annotations

from typing import Callable

from uwgen.idl.model import DefinitionError, Field, MessageDef

MAX_NESTING = 100


class NestingCheck:
    """Checks message types (and every type they use) once each; see the module doc."""

    def __init__(self, lookup: Callable[[str], MessageDef], limit: int = MAX_NESTING):
        self._lookup = lookup
        self.limit = limit
        self._depth: dict[str, int] = {}                 # full name -> levels (checked types)
        self._deepest: dict[str, Field | None] = {}      # the field leading to the deepest child

    def depth(self, msg: MessageDef) -> int:
        """How many levels deep `msg` nests (1: primitives only). Raises DefinitionError for
        a recursive type; does not apply the limit (see `check`)."""
        if msg.full_name in self._depth:
            return self._depth[msg.full_name]
        # Depth-first with an explicit stack: (message, index of the next field to look at).
        stack: list[tuple[MessageDef, int]] = [(msg, 0)]
        on_stack: dict[str, int] = {msg.full_name: 0}
        while stack:
            current, k = stack[-1]
            fields = current.fields
            while k < len(fields) and (fields[k].type.is_primitive
                                       or fields[k].type.base in self._depth):
                k += 1
            if k < len(fields):
                f = fields[k]
                stack[-1] = (current, k + 1)
                base = f.type.base
                if base in on_stack:
                    names = [m.full_name for m, _ in stack[on_stack[base]:]]
                    loop = " -> ".join([*names, base])
                    via = " (through an array)" if f.type.is_array else ""
                    raise DefinitionError(f.where, f"recursive message type: {loop}{via}; a message "
                                                   "cannot contain itself, directly or through others")
                on_stack[base] = len(stack)
                stack.append((self._lookup(base), 0))
                continue
            stack.pop()
            del on_stack[current.full_name]
            best, via = 0, None
            for f in fields:
                if not f.type.is_primitive and self._depth[f.type.base] > best:
                    best, via = self._depth[f.type.base], f
            self._depth[current.full_name] = best + 1
            self._deepest[current.full_name] = via
        return self._depth[msg.full_name]

    def check(self, msg: MessageDef) -> None:
        """DefinitionError if `msg` is recursive or nests deeper than the limit."""
        levels = self.depth(msg)
        if levels <= self.limit:
            return
        chain = [msg.full_name]
        current, level = msg, 1
        while True:
            f = self._deepest[current.full_name]
            if level == self.limit:
                shown = " -> ".join(chain[:3] + (["..."] if len(chain) > 4 else []) + chain[-1:]) \
                    if len(chain) > 4 else " -> ".join(chain)
                raise DefinitionError(
                    f.where, f"{msg.full_name} nests messages {levels} levels deep, over uwgen's "
                             f"limit of {self.limit}: field '{f.name}' of {current.full_name} (level "
                             f"{level}, reached by {shown}) adds level {level + 1}; flatten the "
                             "definition")
            current = self._lookup(f.type.base)
            chain.append(current.full_name)
            level += 1
