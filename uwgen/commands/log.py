"""`uwgen log FILE...`: what a run's recordings say about the link.

    uwgen log demo_output/bridge_surface.mcap demo_output/bridge_vehicle.mcap --plot link.png

FILE: recordings of `uwgen bridge --record` (rotated files of a side too, PATH.1.mcap ...),
of one side or both. Prints each side's span and packets, then the run's table per topic
and service (the demo's, from the recordings alone: uwgen.fieldkit.summary), duplicates and
the slowest message; --plot writes delivery, latency, air use and losses by cause as PNG.
A recording cut short is read up to its last complete chunk and the output says where it
ends. Exit status 0, or 2 when a file is empty, not MCAP, not a uwgen recording or cannot
be read (the message names it).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "summarise bridge recordings (MCAP): the run's table, losses, latency, plots"
EXIT_USAGE = 2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("files", type=Path, nargs="+", metavar="FILE",
                        help="recordings of `uwgen bridge --record` (one side or both)")
    parser.add_argument("--plot", type=Path, metavar="PATH.png",
                        help="also draw delivery, latency, air use and losses by cause here")
    parser.add_argument("--title", default="", help="title of the plot")


def run(args: argparse.Namespace) -> int:
    try:
        from uwgen.fieldkit.reader import RecordingError, read_recordings
    except ImportError as exc:
        print(f"uwgen log: needs the `mcap` package ({exc})", file=sys.stderr)
        return EXIT_USAGE
    from uwgen.fieldkit.summary import format_summary, summarise
    from uwgen import safefile
    for path in args.files:      # a device or a FIFO is never read (it never ends, or blocks)
        why = safefile.problem(path, "recording")
        if why is not None:
            print(f"uwgen log: {why}", file=sys.stderr)
            return EXIT_USAGE
    try:
        recordings = read_recordings(args.files)
    except RecordingError as exc:
        print(f"uwgen log: {exc}", file=sys.stderr)
        return EXIT_USAGE
    summary = summarise(recordings)
    print(format_summary(summary))
    if args.plot:
        from uwgen.fieldkit.plots import plot_summary
        try:
            print(f"plot: {plot_summary(summary, args.plot, args.title)}")
        except OSError as exc:
            print(f"uwgen log: cannot write {args.plot}: {exc.strerror or exc}", file=sys.stderr)
            return EXIT_USAGE
    return 0
