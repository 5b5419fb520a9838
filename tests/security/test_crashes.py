"""No nonce is ever used twice by a sender, however often and wherever it is killed."""
from __future__ import annotations

import random
from pathlib import Path

import pytest

from uwgen.security import guard as guard_module
from uwgen.security import wire
from uwgen.security.keys import SecurityError
from uwgen.security.state import FileIO, StateFile

from .helpers import KEY, surface, twist, vehicle


class Crash(BaseException):
    """The process dies here (BaseException: no handler in the code under test catches it)."""


class CrashingDisk(FileIO):
    """A disk whose files survive crashes; a write is atomic only at its rename, like POSIX."""

    def __init__(self, rng: random.Random):
        self.files: dict[Path, bytes] = {}
        self.rng = rng
        self.steps_left: int | None = None

    def step(self) -> None:
        if self.steps_left is not None:
            self.steps_left -= 1
            if self.steps_left < 0:
                raise Crash()

    def read(self, path):
        return self.files.get(Path(path))

    def write_atomic(self, path, data):
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        self.step()                                        # before anything
        self.files[tmp] = data[:self.rng.randrange(len(data) + 1)]   # torn temporary file
        self.step()
        self.files[tmp] = data                             # written and fsync'd
        self.step()
        self.files[path] = self.files.pop(tmp)             # the rename: old or new, whole
        self.step()                                        # before the folder's fsync


def test_nonce_never_repeats_across_a_thousand_crashes(tmp_path, monkeypatch):
    used: list[tuple[int, int]] = []
    real_seal = wire.seal

    def recording_seal(aead, mode, sender, seq, payload, fingerprint=b"", sync=False):
        used.append((sender, seq))                          # the nonce is (sender, seq)
        return real_seal(aead, mode, sender, seq, payload, fingerprint, sync)
    monkeypatch.setattr(guard_module.wire, "seal", recording_seal)

    rng = random.Random(2024)
    disk = CrashingDisk(rng)
    crashes = clean = 0
    for _ in range(1000):
        disk.steps_left = None
        # a restart: whatever the previous life left on disk must load (never torn)
        g = guard_module.LinkGuard.for_key(KEY, _config(), tmp_path / "s.state", io=disk,
                                           send_block=rng.choice((1, 2, 7, 32)))
        disk.steps_left = rng.randrange(12)                 # die during one of the next writes...
        frames = rng.randrange(120)                         # ...or after this many frames
        try:
            for _ in range(frames):
                g.protect(4, twist())
            if rng.random() < 0.2:
                g.close()
                clean += 1
            else:
                crashes += 1                                # killed between two frames
        except Crash:
            crashes += 1
        g.store.unlock()                                    # a dead process holds no lock
    assert crashes >= 700 and clean > 0
    assert len(used) > 5_000
    assert len(set(used)) == len(used), "a nonce was used twice"


def _config():
    from .helpers import config
    return config(1, 2, "vehicle")


def test_a_write_that_fails_sends_nothing(tmp_path):
    class FullDisk(FileIO):
        def write_atomic(self, path, data):
            raise OSError(28, "No space left on device")
    g = guard_module.LinkGuard.for_key(KEY, _config(), tmp_path / "s.state", io=FullDisk())
    with pytest.raises(SecurityError, match="No space left"):
        g.protect(4, twist())
    assert g.stats()["protect_failed"] == 1 and g.stats()["protected"] == 0


def test_a_damaged_state_file_is_refused(tmp_path):
    (tmp_path / "surface.state").write_text('{"version": 1, "key_id": ')
    with pytest.raises(SecurityError, match="damaged.*new network key"):
        surface(tmp_path)


def test_each_key_has_its_own_state_file(tmp_path):
    from uwgen.security.keys import key_id
    from uwgen.security.state import default_state_path
    from .helpers import OTHER_KEY, config

    def sender(key):
        path = default_state_path(tmp_path / "net.key", "demo", "surface", key_id(key, "demo"))
        return guard_module.LinkGuard.for_key(key, config(1, 2, "vehicle"), path)
    s = sender(KEY)
    for _ in range(5):
        s.protect(4, twist())
    s.close()
    assert sender(OTHER_KEY).stats()["next_seq"] == 0   # a new key starts at 0...
    assert sender(KEY).stats()["next_seq"] == 5         # ...and going back resumes the old one


def test_a_state_file_of_another_key_is_refused(tmp_path):
    from .helpers import OTHER_KEY
    s = surface(tmp_path)
    s.protect(4, twist())
    s.close()
    with pytest.raises(SecurityError, match="belongs to another key"):
        surface(tmp_path, key=OTHER_KEY)


def test_a_clean_stop_skips_no_numbers(tmp_path):
    s = surface(tmp_path)
    for _ in range(5):
        s.protect(4, twist())
    s.close()
    assert surface(tmp_path).stats()["next_seq"] == 5


def test_the_state_file_is_replaced_atomically_and_owner_only(tmp_path):
    s = surface(tmp_path)
    s.protect(4, twist())
    path = tmp_path / "surface.state"
    assert path.stat().st_mode & 0o077 == 0
    assert not (tmp_path / "surface.state.tmp").exists()
    assert StateFile(path, s.state.key_id).load().reserved == s.state.reserved
    v = vehicle(tmp_path)
    assert v.unprotect(s.protect(4, twist())) is not None
