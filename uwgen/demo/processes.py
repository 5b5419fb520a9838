"""The demo's processes: where its package and manifest are, its ROS domains, and a child
process whose output goes to a log file and (filtered) to the console, and `wait_for`, which
waits for the operators while watching the processes that must run throughout.

Shared by the demo (`uwgen.commands.demo`), its drive-away variant (`uwgen.demo.drive_away`)
and the fleet demo (`uwgen.demo.fleet`).
"""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from pathlib import Path

from uwgen import tether

ROOT = Path(__file__).resolve().parents[2]
GENERATED = ROOT / "generated"
PACKAGE = "uwgen_demo"
DEMO_MANIFEST = ROOT / "msg_samples" / "uwgen.yaml"


def domains() -> tuple[int, int]:
    """(vehicle, surface) ROS domain ids: two different ones, derived from ROS_DOMAIN_ID, both in
    0..101 (ROS 2 advises no higher id on Linux: the DDS ports of higher ones lie in the kernel's
    ephemeral port range, where another socket may hold them and discovery fails)."""
    base = int(os.environ.get("ROS_DOMAIN_ID") or (1 + os.getpid() % 100))
    base = base % 101
    return base, base + 1


class Proc:
    """A child process whose merged output goes to a log file and (filtered) to the console,
    and which stops when the demo does (uwgen.tether), even if the demo is killed."""

    def __init__(self, name: str, cmd: list[str], env: dict, out_dir: Path, relay: bool):
        self.name = name
        self.logfile = out_dir / f"{name}.log"
        self._fh = self.logfile.open("w", encoding="utf-8")
        # Tethered: it stops (SIGTERM) if the demo dies without stopping it.
        self.proc = tether.popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True, bufsize=1)
        self._relay = relay
        self._thread = threading.Thread(target=self._pump, name=f"log-{name}", daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self._fh.write(line)
            self._fh.flush()
            if self._relay and self._interesting(line):
                print(f"  [{self.name}] {_strip(line)}", flush=True)
            elif not self._relay and ("ERROR" in line or "Traceback" in line):
                # Quiet: only problems, on stderr.
                print(f"  [{self.name}] {_strip(line)}", file=sys.stderr, flush=True)

    def _interesting(self, line: str) -> bool:
        if self.name == "operator":
            return "[operator]" in line or "ERROR" in line or "WARN" in line
        return "ERROR" in line or "WARN" in line or "Traceback" in line or "Error" in line

    def stop(self, timeout: float = 10.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self._thread.join(timeout=2)
        self._fh.close()
        return self.proc.returncode


    def last_line(self) -> str:
        """The last non-empty line it wrote (what a process that exits says last: its error)."""
        try:
            with self.logfile.open(encoding="utf-8", errors="replace") as fh:
                tail = deque((ln.strip() for ln in fh if ln.strip()), maxlen=1)
        except OSError:
            return ""
        return _strip(tail[0]) if tail else ""


def wait_for(waited: list[Proc], timeout: float, watched: list[Proc],
             poll: float = 0.2) -> Proc | None:
    """Waits up to `timeout` s for every process of `waited` (the operators) to end, watching
    `watched` (bridges, vehicles), which must run until the demo stops them: the first of those
    that ends returns at once (None: all ran throughout). subprocess.TimeoutExpired when
    `waited` have not all ended by then."""
    end = time.monotonic() + timeout
    while True:
        for p in watched:
            if p.proc.poll() is not None:
                return p
        if all(w.proc.poll() is not None for w in waited):
            return None
        if time.monotonic() >= end:
            raise subprocess.TimeoutExpired([w.name for w in waited], timeout)
        time.sleep(poll)


def ended_early(p: Proc) -> str:
    """The line telling that `p`, which should have run throughout, ended."""
    said = p.last_line()
    return (f"uwgen demo: {p.name} ended early (exit {p.proc.returncode})"
            + (f": {said}" if said else "") + f"; stopping (its log: {p.logfile})")


def stop_all(procs: list[Proc]) -> dict[str, int]:
    """Stop `procs`, the last started first: name -> exit code."""
    return {p.name: p.stop() for p in reversed(procs)}


def failures(codes: dict[str, int]) -> dict[str, int]:
    """Those that ended other than cleanly or on our SIGINT (130: Python's exit on it)."""
    return {n: c for n, c in codes.items() if c not in (0, -signal.SIGINT, 130)}


def _strip(line: str) -> str:
    line = line.rstrip()
    # "[INFO] [1700000000.123] [operator]: text" -> "text" (rclpy's console format)
    if line.startswith("[") and "]: " in line:
        level = line[1:line.index("]")]
        text = line.split("]: ", 1)[1]
        return text if level == "INFO" else f"{level}: {text}"
    return line


def _env(domain: int, extra_paths: list[str], iface_env) -> dict:
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    env["PYTHONPATH"] = os.pathsep.join([*extra_paths, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return iface_env.child_env(env)


def network_key(stack: contextlib.ExitStack, out: Path, say, key_file: Path | None = None):
    """The demo's network key (`key_file`, else the manifest's), held (locked) by `stack` while
    the bridges run: a DemoKey, None when the manifest protects nothing, False (after saying
    why) when it is unusable."""
    from uwgen.demo.keys import demo_key
    from uwgen.security.keys import SecurityError
    try:
        key = stack.enter_context(demo_key(DEMO_MANIFEST, out, key_file))
    except (SecurityError, OSError) as exc:
        print(f"uwgen demo: cannot set up the network key: {exc}", file=sys.stderr)
        return False
    if key is not None:
        say(f"  {key.describe()}")
    return key
