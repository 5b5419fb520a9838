#!/usr/bin/env python3
"""Set up uwgen's virtual environment and run its main jobs.

    python3 run.py demo    # set up, then run the demo over an emulated acoustic link
    python3 run.py test    # set up, then check generated/ and run the whole test suite

Prerequisites: Python 3.11, and CMake, a C/C++ compiler and make (checked first): building
rclpy's type support of interface packages (the demo's turtlesim, the tests', `--ros`)
runs ROS's rosidl generators through them. Everything else the project needs is installed here, from the package registry, into
`.venv` (re-installed when pyproject.toml changes). Every ROS process started from
here keeps its discovery on this machine and gets a ROS_DOMAIN_ID of its own.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
STAMP = VENV / ".uwgen-installed"
PY = VENV / "bin" / "python"


def log(msg: str) -> None:
    print(f"[run.py] {msg}", flush=True)


def find_python311() -> str:
    if sys.version_info[:2] == (3, 11):
        return sys.executable
    found = shutil.which("python3.11")
    if found:
        return found
    sys.exit("run.py: uwgen needs Python 3.11 (ROS 2 Jazzy's wheels are built for it); "
             f"this is {sys.version.split()[0]} and no python3.11 is on PATH")


# What building interface type support needs (the same list as uwgen.typesupport.BUILD_TOOLS).
BUILD_TOOLS = ("cmake", "c++", "cc", "make")


def check_tools() -> None:
    missing = [tool for tool in BUILD_TOOLS if shutil.which(tool) is None]
    if missing:
        print(f"run.py: uwgen builds rclpy's type support of interface packages with "
              f"{', '.join(BUILD_TOOLS)}; not on PATH: {', '.join(missing)}. Install them "
              "(Debian/Ubuntu: apt-get install cmake g++ make) and run this again", file=sys.stderr)
        sys.exit(2)


def wanted_stamp() -> str:
    return hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()


def ensure_venv() -> None:
    want = wanted_stamp()
    if PY.exists() and STAMP.exists() and STAMP.read_text().strip() == want:
        return
    if not PY.exists():
        log(f"creating {VENV}")
        subprocess.run([find_python311(), "-m", "venv", str(VENV)], check=True)
    log("installing uwgen with ROS 2 Jazzy (rclpy, common_interfaces, test_msgs, Fast DDS) into .venv")
    subprocess.run([str(PY), "-m", "pip", "install", "--quiet", "--upgrade", "pip"], check=True)
    # --no-compile: Python compiles what it imports when it first imports it, and the test
    # runs read bytecode only from their own folder (PYTHONPYCACHEPREFIX), never the venv's;
    # compiling every installed module up front cost 13 s of the 38 s install.
    subprocess.run([str(PY), "-m", "pip", "install", "--quiet", "--no-compile", "-e",
                    f"{ROOT}[ros,dev]"], check=True)
    STAMP.write_text(want + "\n")


def ros_env() -> dict[str, str]:
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    # A domain of our own so that parallel runs on one machine never cross-talk.
    env.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 100))
    env.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    env["PATH"] = f"{VENV / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONUNBUFFERED"] = "1"
    return env


def run(cmd: list[str], extra_env: dict[str, str] | None = None) -> int:
    log("$ " + " ".join(cmd))
    return subprocess.run(cmd, cwd=ROOT, env={**ros_env(), **(extra_env or {})}).returncode


def test_workers(extra: list[str]) -> list[str]:
    """pytest-xdist options: two workers per core (at least 3, at most 4: many tests wait on
    sockets, ROS and the emulator, not on the CPU, so on 2 cores fewer than 4 workers leave
    it idle for a good part of the run), unless the caller chose (`-n ...`, `-p no:xdist`)."""
    if any(a == "-n" or a.startswith(("-n", "--numprocesses", "--dist")) or a == "no:xdist"
           for a in extra):
        return []
    # worksteal: a worker that runs out takes tests queued for another, so the run does not
    # end with one worker alone on its backlog while the others idle
    return ["-n", str(max(3, min(2 * (os.cpu_count() or 2), 4))), "--dist", "worksteal"]


def cmd_test(extra: list[str]) -> int:
    # Everything the run writes goes to one temporary folder, removed at its end: uwgen's
    # cache, Hypothesis's and pytest's, the bytecode (tests/conftest.py, which writes it there
    # even where PYTHONDONTWRITEBYTECODE is set), never the checkout or ~/.cache/uwgen.
    with tempfile.TemporaryDirectory(prefix="uwgen-test-") as run_dir:
        extra_env = {"UWGEN_TEST_RUN_DIR": run_dir, "UWGEN_CACHE": str(Path(run_dir) / "cache"),
                     "PYTHONPYCACHEPREFIX": str(Path(run_dir) / "pycache")}
        rc = run([str(VENV / "bin" / "uwgen"), "build", "--check"], extra_env)
        if rc != 0:
            log("generated/ is stale: run `.venv/bin/uwgen build` and commit the result")
            return rc
        rc = run([str(PY), "-m", "pytest", *test_workers(extra), *extra], extra_env)
    if rc == 5:  # pytest: no tests collected; a suite that runs nothing must not pass
        log("pytest collected no tests")
        return 1
    return rc


def cmd_demo(extra: list[str]) -> int:
    return run([str(VENV / "bin" / "uwgen"), "demo", *extra])


def main(argv: list[str]) -> int:
    jobs = {"test": cmd_test, "demo": cmd_demo}
    if not argv or argv[0] not in jobs:
        print(__doc__.strip())
        return 2
    check_tools()
    find_python311()
    ensure_venv()
    return jobs[argv[0]](argv[1:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
