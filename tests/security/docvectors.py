"""The worked bytes of a part of docs/wire-format.md, as the tests that recompute them read them."""
from __future__ import annotations

import re
from pathlib import Path

DOC = Path(__file__).resolve().parents[2] / "docs" / "wire-format.md"


def vectors(section: str) -> dict[str, bytes]:
    """Every `name hex hex ...` line of the fenced blocks of `section` (text of the doc)."""
    out = {}
    for block in re.findall(r"```\n(.*?)```", section, re.S):
        for line in block.strip().splitlines():
            name, hexes = line.split(None, 1)
            out[name] = bytes.fromhex(hexes.replace(" ", ""))
    return out
