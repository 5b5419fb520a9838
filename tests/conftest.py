"""Shared test set-up: every ROS process the tests start stays on this machine, every file
the tests write goes to a temporary folder of this run.

- ROS: discovery on localhost only, and a block of domain ids for each pytest process
  (tests/ros_domains.py), so parallel workers (pytest-xdist) never share a domain.
- Files: uwgen's cache ($UWGEN_CACHE: type-support builds, the demo's fall-backs) and
  Hypothesis's example database are a folder made for this run, shared by its workers and
  removed at its end; the user's ~/.cache/uwgen is never touched. `run.py test` makes that
  folder (and sends Python's bytecode there too); a bare `pytest` makes its own.
- At the end of the run the checkout must hold no file it did not hold at its start
  (`git status --ignored`); a run that left one fails and names it. pytest's own cache is
  in the run's folder too (pyproject: cache_dir), so `--lf` knows only the current run.
"""
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import ros_domains

RUN_DIR_ENV = "UWGEN_TEST_RUN_DIR"
ROOT = Path(__file__).resolve().parents[1]

# Before anything imports rclpy: discovery only on localhost, and a domain of our own.
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
ros_domains.setup()

# The run's folder: made by run.py, or here by the run's first process (xdist's controller
# runs this file before it starts the workers, which inherit the variable).
_OWN_RUN_DIR = RUN_DIR_ENV not in os.environ
if _OWN_RUN_DIR:
    os.environ[RUN_DIR_ENV] = tempfile.mkdtemp(prefix="uwgen-test-")
RUN_DIR = Path(os.environ[RUN_DIR_ENV])
os.environ["UWGEN_CACHE"] = str(RUN_DIR / "cache")
os.environ["HYPOTHESIS_STORAGE_DIRECTORY"] = str(RUN_DIR / "hypothesis")
# Bytecode of the checkout's modules, here and in every child process (run.py sets it too),
# written there even where PYTHONDONTWRITEBYTECODE keeps checkouts clean: it is outside them.
# Without it every process the tests start compiled every module it imported, and every
# worker (started after this file ran, with its environment) rewrote every test module.
os.environ.setdefault("PYTHONPYCACHEPREFIX", str(RUN_DIR / "pycache"))
sys.pycache_prefix = os.environ["PYTHONPYCACHEPREFIX"]
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
sys.dont_write_bytecode = False

from hypothesis import HealthCheck, settings  # noqa: E402  (after its storage folder is set)
from hypothesis.database import DirectoryBasedExampleDatabase  # noqa: E402

# Property tests prove behaviour, never speed (speed is for benchmarks/): no per-example
# deadline and no "input generation is slow" check, which failed runs on a loaded machine
# (an example took 2.8 s against a 2 s deadline; 4 inputs in 3 s) with nothing wrong.
settings.register_profile("uwgen", database=DirectoryBasedExampleDatabase(str(RUN_DIR / "hypothesis")),
                          deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("uwgen")


def _checkout_files() -> set[str] | None:
    """Every path `git status` reports in the checkout, ignored ones included (None: no git)."""
    try:
        res = subprocess.run(["git", "status", "--porcelain", "--ignored", "--untracked-files=all"],
                             cwd=ROOT, capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if res.returncode != 0:
        return None
    paths = {line[3:] for line in res.stdout.splitlines()}
    return {p for p in paths if not p.startswith((".venv/", "uwgen.egg-info/"))}


def _is_worker(config) -> bool:
    return hasattr(config, "workerinput")


# The demo's turtlesim type support is a C build (25-45 s) that several tests on either
# worker need; each waits for it under uwgen.typesupport's file lock. Started in the
# background as the run begins, it is built while the workers run other tests, instead of
# keeping one worker idle behind the lock when the first such test comes.
PREBUILD = "from pathlib import Path; from uwgen.typesupport import ensure_interfaces; ensure_interfaces(Path({!r}))"


def _prebuild():
    from uwgen import tether
    return tether.popen([sys.executable, "-c", PREBUILD.format(str(ROOT / "msg_samples" / "turtlesim"))],
                        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


# Tests marked slow run for up to a minute, mostly waiting. Left where they are collected,
# one may come last and run alone while the other workers have finished (47 s of a 328 s
# run on 2 cores).
# pytest-xdist's worksteal first hands worker i the next len(pending) // (workers - i) tests
# of the collection; each slow test goes to the head of one such share, longest first
# (`seconds` in its mark), so they start with the run. Stealing balances the rest.
def pytest_collection_modifyitems(config, items):
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0"))
    if workers < 2:
        return
    marks = [(it, it.get_closest_marker("slow")) for it in items]
    slow = [it for it, mark in sorted((m for m in marks if m[1]),
                                      key=lambda m: -m[1].kwargs.get("seconds", 30))]
    rest = [it for it, mark in marks if not mark]
    ordered, pending = [], len(items)
    for i in range(workers):
        share = pending // (workers - i)
        pending -= share
        head = slow[i::workers]
        fill = max(0, share - len(head))
        ordered += head + rest[:fill]
        del rest[:fill]
    items[:] = ordered + rest


def pytest_configure(config):
    if not _is_worker(config):
        config._uwgen_checkout_before = _checkout_files()
        if getattr(config.option, "numprocesses", None):      # only worth it with workers
            config._uwgen_prebuild = _prebuild()


def pytest_sessionfinish(session, exitstatus):
    config = session.config
    if _is_worker(config):
        return
    before = getattr(config, "_uwgen_checkout_before", None)
    after = _checkout_files()
    if before is None or after is None:
        return
    left = sorted(after - before)
    if left:
        reporter = config.pluginmanager.get_plugin("terminalreporter")
        text = "the tests left files in the checkout (write them under tmp_path):\n  " + "\n  ".join(left)
        if reporter:
            reporter.write_line(text, red=True)
        else:
            print(text)
        session.exitstatus = 1


def pytest_unconfigure(config):
    build = getattr(config, "_uwgen_prebuild", None)
    if build is not None and build.poll() is None:            # a run shorter than the build
        build.terminate()
        build.wait(timeout=30)
    if _OWN_RUN_DIR and not _is_worker(config):
        shutil.rmtree(RUN_DIR, ignore_errors=True)
