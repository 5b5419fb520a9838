"""The demo's path plot: the commanded square, the vehicle's own path and the poses the
surface received."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from uwgen import pngplot


def plot_paths(report: Any, path: Path, title: str = "") -> Path:
    return pngplot.save(path_figure(report, title), path)


def path_figure(report: Any, title: str = ""):
    """The figure of the commanded and reported paths (the caller saves and closes it)."""
    plt = pngplot.pyplot()

    fig, ax = plt.subplots(figsize=(6.4, 6.0), dpi=110)
    if report.commanded:
        xs, ys = zip(*report.commanded)
        ax.plot(xs, ys, "--", color="tab:blue", lw=2, label="commanded square (operator's waypoints)")
    if report.truth:
        xs, ys = zip(*report.truth)
        ax.plot(xs, ys, "-", color="0.6", lw=1, label="vehicle (simulator, local)")
    if report.reported:
        xs, ys = zip(*report.reported)
        ax.plot(xs, ys, "o", color="tab:orange", ms=3.5, label="reported (poses received at surface)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.3)
    # Below the axes, never over the square: the paths fill the plot.
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8, frameon=False)
    ax.set_title(title or "uwgen demo: commanded vs reported path", fontsize=10)
    fig.tight_layout()
    return fig

