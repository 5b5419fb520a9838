"""Child processes that die with the process that started them.

A child of `popen` or `run` gets SIGTERM when its parent dies, however it dies (SIGKILL
too): an interrupted test run or demo leaves no bridge, vehicle or emulator behind to share
the next run's ROS graph. The orderly stop (SIGINT, a timeout, then SIGKILL) stays the
caller's; this is only the safety net under it.

How (Linux): the child is first this file, run by a bare interpreter; it asks the kernel
for SIGTERM on its parent's death (prctl PR_SET_PDEATHSIG, which holds across exec), checks
that its parent is still the process that started it (a parent that died before the prctl
sends nothing), and then execs the command: same pid, same streams, same environment.
Not `preexec_fn`: the callers have threads (log pumps, the emulator, rclpy executors), and
`preexec_fn` runs Python between fork and exec, where a lock another thread held stays
locked. The kernel ties the signal to the *thread* that started the child: start children
from a thread that lives as long as they should (the main thread, as every caller here).

Elsewhere (macOS, Windows) the command runs as given: no such kernel feature, so only the
orderly stop applies.

This module imports nothing of uwgen: it runs as a script (`python -I -S tether.py`).
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys

LINUX = sys.platform.startswith("linux")
PR_SET_PDEATHSIG = 1          # <linux/prctl.h>
EXIT_CANNOT_EXEC = 127        # as a shell's "command not found"


def tethered(argv: list[str], env: dict | None = None) -> list[str]:
    """`argv` prefixed so that, started by this process, it gets SIGTERM when this process
    dies. A command without a slash is looked up on `env`'s PATH (else this process's), as
    subprocess does; FileNotFoundError when it is not there, as subprocess raises."""
    argv = [os.fspath(a) for a in argv]
    if not LINUX:
        return argv        # no PR_SET_PDEATHSIG: the caller's orderly stop is all there is
    program = argv[0]
    if os.sep not in program:
        path = (env or os.environ).get("PATH", os.defpath)
        found = shutil.which(program, path=path)
        if found is None:
            raise FileNotFoundError(2, f"No such file or directory: {program!r}")
        program = found
    return [sys.executable, "-I", "-S", __file__, str(os.getpid()), program, *argv[1:]]


def popen(argv: list[str], **kwargs) -> subprocess.Popen:
    """subprocess.Popen of `argv`, whose process gets SIGTERM when this process dies."""
    return subprocess.Popen(tethered(argv, kwargs.get("env")), **kwargs)


def run(argv: list[str], **kwargs) -> subprocess.CompletedProcess:
    """subprocess.run of `argv`, whose process gets SIGTERM when this process dies."""
    return subprocess.run(tethered(argv, kwargs.get("env")), **kwargs)


def tether_to(parent: int) -> None:
    """Ask for SIGTERM when the parent dies; if `parent` is already gone (this process was
    re-parented before the request), take the SIGTERM now."""
    import ctypes
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"prctl(PR_SET_PDEATHSIG): {os.strerror(err)}")
    if os.getppid() != parent:
        os.kill(os.getpid(), signal.SIGTERM)
        os._exit(128 + signal.SIGTERM)      # reached only if SIGTERM is ignored


def main(args: list[str]) -> None:
    """`tether.py PARENT_PID PROGRAM ARG...`: tether this process to PARENT_PID, then exec."""
    parent, program = int(args[0]), args[1]
    tether_to(parent)
    # This interpreter ignores SIGPIPE and SIGXFSZ; an ignored signal stays ignored across
    # exec, and the command must start with the defaults, as from subprocess directly.
    for sig in (signal.SIGPIPE, signal.SIGXFSZ):
        signal.signal(sig, signal.SIG_DFL)
    try:
        os.execv(program, args[1:])
    except OSError as exc:
        print(f"uwgen: cannot start {program}: {exc.strerror}", file=sys.stderr)
        os._exit(EXIT_CANNOT_EXEC)


if __name__ == "__main__":
    main(sys.argv[1:])
