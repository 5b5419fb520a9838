"""Hygiene (docs/security.md): one copy of a side at a time, writes that never follow a symlink
and whose every byte is checked, security modes in the schema fingerprint; and no state file
left to be absurd, restored or shared."""
from __future__ import annotations

import os

import pytest

from uwgen.codegen.fingerprint import description, digest
from uwgen.security import files
from uwgen.security.errors import SecurityError
from uwgen.security.guard import LinkGuard
from uwgen.security.keys import read_key_file, write_key_file

from .helpers import surface, twist, vehicle


def test_a_second_copy_of_a_side_is_refused_while_the_first_runs(tmp_path):
    first = surface(tmp_path)
    with pytest.raises(SecurityError, match="already running.*second copy"):
        surface(tmp_path)
    first.close()
    surface(tmp_path).close()                       # once the first stopped, it may start


def test_an_old_state_file_is_never_read_even_absurd(tmp_path):
    # Earlier versions kept sequence numbers in <key>.<network>.<side>.<key id>.state; nothing
    # reads it now: an absurd one ("reserved": 1e999, past 2^43) changes nothing.
    for name in ("surface.state", "vehicle.state"):
        (tmp_path / name).write_text('{"version": 1, "reserved": 1e999, "floors": {"1": 9e99}}')
    s, v = surface(tmp_path), vehicle(tmp_path)
    assert v.unprotect(s.protect(4, twist(1.0))) == twist(1.0)
    assert s.stats()["next_seq"] == 1


def test_the_lock_file_is_never_followed_through_a_symlink(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    (tmp_path / "surface.lock").symlink_to(victim)
    with pytest.raises(SecurityError, match="cannot open the lock file"):
        surface(tmp_path)
    assert victim.read_text() == "precious\n"


def test_keygen_never_follows_a_planted_tmp_symlink(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    (tmp_path / "net.key.tmp").symlink_to(victim)
    key = write_key_file(tmp_path / "net.key")
    assert victim.read_text() == "precious\n"
    assert read_key_file(tmp_path / "net.key") == key


def test_keygen_force_replaces_a_symlinked_key_file_not_its_target(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    (tmp_path / "net.key").symlink_to(victim)
    with pytest.raises(SecurityError, match="exists"):
        write_key_file(tmp_path / "net.key")
    write_key_file(tmp_path / "net.key", force=True)
    assert victim.read_text() == "precious\n" and not (tmp_path / "net.key").is_symlink()


def test_short_writes_are_completed_and_a_stalled_write_is_an_error(tmp_path, monkeypatch):
    real = os.write
    monkeypatch.setattr(files.os, "write", lambda fd, data: real(fd, bytes(data[:1])))
    files.write_private(tmp_path / "f", b"every byte\n")
    assert (tmp_path / "f").read_bytes() == b"every byte\n"
    monkeypatch.setattr(files.os, "write", lambda fd, data: 0)
    with pytest.raises(OSError, match="wrote nothing"):
        files.write_private(tmp_path / "f", b"new content\n")
    assert (tmp_path / "f").read_bytes() == b"every byte\n"      # the old content, whole
    assert not (tmp_path / "f.tmp").exists()


def test_the_security_mode_is_in_the_schema_fingerprint():
    from uwgen.codegen.ir import IRBuilder
    from uwgen.idl.loader import InterfaceLibrary
    lib = InterfaceLibrary([], installed=True)
    ct = IRBuilder(lib.get).codec(lib.get("std_msgs/msg/Bool"), "native")
    fp = {mode: digest(description("topic", [0], 7, "native", "std_msgs/msg/Bool", [ct],
                                   {ct.key: ct}, security=mode)) for mode in ("off", "sign", "encrypt")}
    assert len(set(fp.values())) == 3
    plain = description("topic", [0], 7, "native", "std_msgs/msg/Bool", [ct], {ct.key: ct})
    assert digest(plain) == fp["off"] and len(plain) == 10     # unprotected ids: no mode item
