"""Long work that says what it does: a file lock that names itself and who holds it while
it waits, and build steps that report their progress (type-support builds, uwgen.typesupport).

    with locked(folder, "building turtlesim's type support", say=log.info):
        run_steps([("configure", ["cmake", ...]), ("compile", ["make"])], cwd, env, logfile,
                  "turtlesim", say=log.info)

The lock is `folder/.lock` (flock): its holder writes its pid and what it does into it, so
a second uwgen waiting on it says whose lock it waits for, at once and every WAIT_NOTE
seconds. Waits take an injectable clock and sleep.
"""
from __future__ import annotations

import fcntl
import os
import re
import subprocess
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

WAIT_NOTE = 10.0       # s between "still waiting" lines
POLL = 0.2             # s between tries of a held lock
PERCENT_STEP = 25      # report make's progress every this many percent

Say = Callable[[str], None]
_MAKE_PERCENT = re.compile(rb"^\[\s*(\d+)%\]")


class LockError(OSError):
    pass


@contextmanager
def locked(folder: Path, doing: str, *, say: Say, clock: Callable[[], float] = time.monotonic,
           sleep: Callable[[float], None] = time.sleep) -> Iterator[None]:
    """Hold `folder/.lock` while the block runs; if another process holds it, say so (with
    what it wrote: its pid and what it does) and wait. OSError if the folder is unwritable."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / ".lock"
    with path.open("a+") as fh:
        start = last = None
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                now = clock()
                if start is None:
                    start = last = now
                    say(f"waiting for the lock {path}, held by {_holder(path)}")
                elif now - last >= WAIT_NOTE:
                    last = now
                    say(f"still waiting for the lock {path} ({now - start:.0f} s), held by "
                        f"{_holder(path)}")
                sleep(POLL)
        if start is not None:
            say(f"got the lock {path} after {clock() - start:.0f} s")
        try:
            fh.seek(0)
            fh.truncate()
            fh.write(f"pid {os.getpid()}: {doing}\n")
            fh.flush()
            yield
        finally:
            fh.seek(0)
            fh.truncate()
            fh.flush()
            fcntl.flock(fh, fcntl.LOCK_UN)


def _holder(path: Path) -> str:
    try:
        text = path.read_text(encoding="utf-8").strip()
    except OSError:
        text = ""
    return text or "another uwgen process (it did not say which)"


def run_steps(steps: list[tuple[str, list[str]]], cwd: Path, env: dict, logfile: Path, what: str,
              *, say: Say, clock: Callable[[], float] = time.monotonic) -> tuple[int, list[str]] | None:
    """Run each (name, command) in turn with its output in `logfile`, saying when each starts
    and ends, and make's percentages as they pass each PERCENT_STEP. None when all succeed,
    else (exit status, command) of the one that failed."""
    with logfile.open("wb") as out:
        for n, (name, cmd) in enumerate(steps, 1):
            say(f"{what}: step {n}/{len(steps)}, {name} ...")
            start, shown = clock(), 0
            proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT)
            assert proc.stdout is not None
            for line in proc.stdout:
                out.write(line)
                m = _MAKE_PERCENT.match(line)
                if m and int(m.group(1)) >= shown + PERCENT_STEP:
                    shown = int(m.group(1)) // PERCENT_STEP * PERCENT_STEP
                    say(f"{what}: {name} {shown}%")
            code = proc.wait()
            if code != 0:
                return code, cmd
            say(f"{what}: {name} done in {clock() - start:.0f} s")
    return None
