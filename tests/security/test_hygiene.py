"""Hygiene of the security state (issue 17, item 5): one copy of a side at a time, the sender
id recorded and checked, every number range-checked with a clear error, writes that never
follow a symlink and whose every byte is checked, security modes in the schema fingerprint."""
from __future__ import annotations

import json
import os

import pytest

from uwgen.codegen.fingerprint import description, digest
from uwgen.security import files
from uwgen.security.errors import SecurityError
from uwgen.security.guard import LinkGuard
from uwgen.security.keys import key_id, read_key_file, write_key_file
from uwgen.security.state import FileIO, StateFile

from .helpers import KEY, config, surface


def test_a_second_copy_of_a_side_is_refused_while_the_first_runs(tmp_path):
    first = surface(tmp_path)
    with pytest.raises(SecurityError, match="already running.*second copy"):
        surface(tmp_path)
    first.close()
    surface(tmp_path).close()                       # once the first stopped, it may start


def test_a_state_file_of_another_sender_id_is_refused(tmp_path):
    path = tmp_path / "side.state"
    g = LinkGuard.for_key(KEY, config(1, 2, "vehicle"), path)
    g.protect(4, bytes([0, 4, 0xF5]))
    g.close()
    assert json.loads(path.read_text())["sender"] == 1
    with pytest.raises(SecurityError, match="written for sender id 1.*this side is sender 3"):
        LinkGuard.for_key(KEY, config(3, 2, "vehicle"), path)


@pytest.mark.parametrize("field, value, why", [
    ("reserved", "1e999", "reserved is inf, not an integer"),
    ("reserved", str(2 ** 43 + 5), "reserved = 8796093022213 is out of range"),
    ("reserved", "-1", "reserved = -1 is out of range"),
    ("reserved", "true", "reserved is True, not an integer"),
    ("reserved", "12.0", "reserved is 12.0, not an integer"),
    ("floors", '{"2": 1e999}', "floors.2 is inf"),
    ("floors", '{"2": 8796093022208}', "floors.2 = 8796093022208 is out of range"),
    ("floors", '{"x": 3}', "key 'x' is not a sender id"),
    ("floors", '{"99": 3}', "floors key 99 = 99 is out of range"),
    ("floors", "[]", "floors is not an object"),
    ("sender", '"one"', "sender is 'one', not an integer"),
    ("sender", "16", "sender = 16 is out of range"),
])
def test_absurd_numbers_in_the_state_file_are_refused_with_the_field(tmp_path, field, value, why):
    fields = {"version": "2", "key_id": json.dumps(key_id(KEY, "demo")), "sender": "1",
              "reserved": "0", "floors": "{}"}
    fields[field] = value
    (tmp_path / "surface.state").write_text(
        "{" + ", ".join(f'"{k}": {v}' for k, v in fields.items()) + "}")
    with pytest.raises(SecurityError, match="is damaged") as err:
        surface(tmp_path)
    assert why in str(err.value)


def test_a_refused_state_file_leaves_the_side_lock_free(tmp_path):
    (tmp_path / "surface.state").write_text('{"version": 2, "reserved": 1e999}')
    with pytest.raises(SecurityError):
        surface(tmp_path)
    (tmp_path / "surface.state").unlink()
    surface(tmp_path).close()                       # not "already running"


def test_the_state_writer_never_follows_a_planted_tmp_symlink(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    (tmp_path / "surface.state.tmp").symlink_to(victim)
    g = surface(tmp_path)
    g.protect(4, bytes([0, 4, 0xF5]))               # reserves a block: writes the state file
    g.close()
    assert victim.read_text() == "precious\n"
    assert not (tmp_path / "surface.state").is_symlink()
    assert json.loads((tmp_path / "surface.state").read_text())["reserved"] == 1


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


def test_a_state_write_that_stalls_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setattr(files.os, "write", lambda fd, data: 0)
    store = StateFile(tmp_path / "s.state", key_id(KEY, "demo"), FileIO(), sender=1)
    with pytest.raises(SecurityError, match="cannot write security state file"):
        store.save(store.load())


def test_the_security_mode_is_in_the_schema_fingerprint():
    from uwgen.codegen.ir import IRBuilder
    from uwgen.idl.loader import InterfaceLibrary
    lib = InterfaceLibrary([], installed=True)
    ct = IRBuilder(lib.get).codec(lib.get("std_msgs/msg/Bool"), "native")
    fp = {mode: digest(description("topic", [0], 7, "native", "std_msgs/msg/Bool", [ct],
                                   {ct.key: ct}, mode)) for mode in ("off", "sign", "encrypt")}
    assert len(set(fp.values())) == 3
    plain = description("topic", [0], 7, "native", "std_msgs/msg/Bool", [ct], {ct.key: ct})
    assert digest(plain) == fp["off"] and len(plain) == 9      # unprotected ids: as before
