"""Numbers on uwgen's command lines, range-checked as argparse reads them.

`type=float` takes `1e400` (inf), `nan` and `1e-300` and `type=int` takes a 400-digit
number; each then ends in an OverflowError, a division by zero or a run that never ends
(`--nodes 100000000`) far from the flag that caused it. These types refuse them where they
are read: `uwgen emulate: error: argument --period: must be a number in 0.001..3600, got 1e400`.

    parser.add_argument("--period", type=number(0.001, 3600))
    parser.add_argument("--nodes", type=whole(1, 1000))
"""
from __future__ import annotations

import argparse
import math


def _shown(text: str) -> str:
    return text if len(text) <= 24 else f"{text[:24]}... ({len(text)} characters)"


def number(lo: float, hi: float, *, above: bool = False):
    """A finite float in lo..hi (with `above`, strictly greater than lo)."""
    def parse(text: str) -> float:
        span = f"more than {lo:g}, at most {hi:g}" if above else f"{lo:g}..{hi:g}"
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number in {span}, got {_shown(text)!r}") from None
        if not math.isfinite(value) or value > hi or value < lo or (above and value == lo):
            raise argparse.ArgumentTypeError(f"must be a number in {span}, got {_shown(text)}")
        return value
    parse.__name__ = "number"
    return parse


def whole(lo: int, hi: int):
    """An integer in lo..hi (written in at most 20 digits: no 400-digit conversions)."""
    def parse(text: str) -> int:
        digits = text.strip().lstrip("+-")
        if not digits.isascii() or not digits.isdigit() or len(digits) > 20:
            raise argparse.ArgumentTypeError(f"must be a whole number in {lo}..{hi}, got {_shown(text)!r}")
        value = int(text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be a whole number in {lo}..{hi}, got {_shown(text)}")
        return value
    parse.__name__ = "whole number"
    return parse


def caller_path(text: str):
    """A path as the caller means it: `~` expanded, and a relative one made absolute against
    the folder the command was started in, at once. A command that hands the path to child
    processes running elsewhere (the demo's run in the checkout) would otherwise have them
    write where the caller never looks."""
    from pathlib import Path
    if not text:
        raise argparse.ArgumentTypeError("must be a path, got ''")
    return Path(text).expanduser().absolute()
