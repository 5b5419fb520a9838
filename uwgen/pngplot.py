"""PNG plots without a display: the one way uwgen draws (the demo's path and drive-away
plots, the emulator's PDR sweep, `uwgen log --plot`). matplotlib is imported when a plot is
drawn, never when a module is loaded."""
from __future__ import annotations

from pathlib import Path
from typing import Any


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save(fig: Any, path: str | Path) -> Path:
    """Write `fig` to `path` (its folder made as needed) and free it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    pyplot().close(fig)
    return path
