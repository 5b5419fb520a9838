"""ROS domain ids of the tests: every pytest process gets a block of ids of its own.

With parallel workers (pytest-xdist) each worker is one process with its own block, so two
workers never share a domain; without them the one process has the whole range. Inside its
block a process uses its ROS_DOMAIN_ID (and the id after it, as `uwgen demo` does) for
children that take the domain from the environment, and `next_domain()` for the contexts a
test creates itself. The starting points come from the ROS_DOMAIN_ID the run was given
(run.py derives it from its pid), so two runs on one machine are unlikely to meet.
"""
from __future__ import annotations

import itertools
import os

# ROS 2 advises ids 0..101 on Linux: from 102 on, a domain's DDS ports (7400 + 250 * id + ...)
# lie in the kernel's ephemeral range (32768..60999), where any TCP socket of the run (the
# emulator's, a bridge's) may hold the port a participant needs, and discovery then fails now
# and then (a walkthrough listener that heard nothing in 120 s). 0 is everyone's default.
FIRST, LAST = 1, 101
BLOCK_MIN = 3                 # a process's ROS_DOMAIN_ID, the id after it, one for its tests
DEMO_LIMIT = 100              # `uwgen demo` takes ROS_DOMAIN_ID % 101 and the id after it
SEED_ENV = "UWGEN_TEST_DOMAIN_SEED"
# A narrower range, "FIRST-LAST" inside 1..101, keeps the tests away from other ROS work on
# the machine (a benchmark running in domains 80-89: UWGEN_TEST_DOMAINS=1-79).
RANGE_ENV = "UWGEN_TEST_DOMAINS"


def _range() -> tuple[int, int]:
    text = os.environ.get(RANGE_ENV, "").strip()
    if not text:
        return FIRST, LAST
    try:
        first, last = (int(part) for part in text.split("-"))
    except ValueError:
        raise SystemExit(f"{RANGE_ENV}={text!r}: expected FIRST-LAST, e.g. 1-79") from None
    if not (FIRST <= first <= last <= LAST and last - first + 1 >= BLOCK_MIN):
        raise SystemExit(f"{RANGE_ENV}={text!r}: a range inside {FIRST}-{LAST} of at least "
                         f"{BLOCK_MIN} ids")
    return first, last


def _worker() -> tuple[int, int]:
    """(index, count) of this pytest process among the run's workers."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    index = int(name[2:]) if name.startswith("gw") and name[2:].isdigit() else 0
    return index, max(count, index + 1)


def block() -> range:
    index, count = _worker()
    first, last = _range()
    size = (last - first + 1) // count
    if size < BLOCK_MIN:        # else next_domain() would find no id of its own, forever
        raise SystemExit(f"{RANGE_ENV}: {last - first + 1} ids ({first}-{last}) for {count} test "
                         f"processes; each needs {BLOCK_MIN} (its ROS_DOMAIN_ID, the id after "
                         f"it, one for its tests' contexts): give at least {BLOCK_MIN * count}")
    return range(first + index * size, first + (index + 1) * size)


def _seed() -> int:
    return int(os.environ[SEED_ENV])


def setup() -> int:
    """Set this process's ROS_DOMAIN_ID (inside its block) once; returns it."""
    if SEED_ENV not in os.environ:      # the run's first process: remember what it was given
        os.environ[SEED_ENV] = os.environ.get("ROS_DOMAIN_ID") or str(1 + os.getpid() % 100)
    ids = block()
    choices = max(1, min(len(ids) - 1, DEMO_LIMIT - ids.start))
    domain = ids.start + _seed() % choices
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    return domain


_counter = itertools.count()


def next_domain() -> int:
    """A ROS domain id of this process's block for every context a test creates, never the
    process's ROS_DOMAIN_ID nor the one after it."""
    ids = block()
    own = int(os.environ["ROS_DOMAIN_ID"])
    while True:
        domain = ids.start + (_seed() * 7 + next(_counter)) % len(ids)
        if domain not in (own, own + 1):
            return domain
