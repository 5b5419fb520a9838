"""Knocking on uwgen's doors: run a command in this process and sort what came out.

Every door (a manifest, a .msg/.srv/.action text, a command line, a key or state file) must
answer bad input with a clear error (a located `file:line:column` where there is a file) or
with success; never with a traceback. `cli()` runs `uwgen ARGS` in this process, so any
exception other than argparse's exit fails the calling test with its traceback.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from uwgen.cli import main as uwgen_main

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "msg_samples"


def cli(capsys, *argv: str) -> tuple[int, str]:
    """(exit status, stdout + stderr) of `uwgen ARGV` run here; argparse's exit is status 2."""
    try:
        rc = uwgen_main([str(a) for a in argv])
    except SystemExit as exc:   # argparse: usage error (2) or --help (0)
        rc = exc.code if isinstance(exc.code, int) else 2
    out = capsys.readouterr()
    return rc, out.out + out.err


def bounded(code: str, seconds: float = 20.0, argv: list[str] = ()) -> subprocess.CompletedProcess:
    """Run Python `code` in a child process that must finish within `seconds` (a hang, such
    as a regular expression backtracking for minutes, fails the test instead of blocking the
    suite: a hung C regex cannot be interrupted in this process)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    try:
        return subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True,
                              timeout=seconds, env=env, cwd=ROOT)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"still running after {seconds} s: {code}") from None
