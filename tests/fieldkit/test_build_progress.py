"""Long builds say what they do: a held lock is named with its holder while we wait, and
build steps report their start, progress and end."""
from __future__ import annotations

import sys
import threading

from uwgen.buildsteps import WAIT_NOTE, locked, run_steps


class Steps:
    """A clock that moves only when the waiter sleeps."""

    def __init__(self):
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def test_a_wait_on_a_held_lock_names_the_lock_and_its_holder(tmp_path):
    said: list[str] = []
    held, release = threading.Event(), threading.Event()

    def holder():
        with locked(tmp_path, "building the type support of turtlesim", say=lambda s: None):
            held.set()
            release.wait(10)
    t = threading.Thread(target=holder)
    t.start()
    held.wait(5)
    clock = Steps()

    def sleep(s):
        clock.sleep(s)
        if clock.t > WAIT_NOTE * 2.5:
            release.set()
            t.join(5)
    with locked(tmp_path, "me", say=said.append, clock=clock.now, sleep=sleep):
        pass
    lock = tmp_path / ".lock"
    assert said[0] == (f"waiting for the lock {lock}, held by pid "
                       f"{__import__('os').getpid()}: building the type support of turtlesim")
    assert sum("still waiting" in s for s in said) == 2
    assert said[-1].startswith(f"got the lock {lock} after ")


def test_an_untaken_lock_is_taken_silently(tmp_path):
    said: list[str] = []
    with locked(tmp_path, "me", say=said.append):
        assert "me" in (tmp_path / ".lock").read_text()
    assert said == [] and (tmp_path / ".lock").read_text() == ""


def test_build_steps_report_start_progress_and_end(tmp_path):
    said: list[str] = []
    script = "import sys\nfor p in (10, 30, 55, 80, 100): print(f'[{p:3d}%] Building x')"
    failed = run_steps([("compile", [sys.executable, "-c", script])], tmp_path, {}, tmp_path / "b.log",
                       "type support of demo", say=said.append)
    assert failed is None
    assert said[0] == "type support of demo: step 1/1, compile ..."
    assert [s for s in said if s.endswith("%")] == [
        "type support of demo: compile 25%", "type support of demo: compile 50%",
        "type support of demo: compile 75%", "type support of demo: compile 100%"]
    assert said[-1].startswith("type support of demo: compile done in ")
    assert "[ 55%] Building x" in (tmp_path / "b.log").read_text()


def test_a_failing_step_stops_the_build_and_says_which(tmp_path):
    said: list[str] = []
    failed = run_steps([("a", [sys.executable, "-c", "raise SystemExit(3)"]),
                        ("b", [sys.executable, "-c", "pass"])], tmp_path, {}, tmp_path / "b.log",
                       "x", say=said.append)
    assert failed is not None and failed[0] == 3
    assert not any("step 2/2" in s for s in said)
