"""Key files: `uwgen keygen` writes owner-only keys and never replaces one by accident;
keys that others can read, or that are malformed, are refused with a clear message."""
from __future__ import annotations

import os

import pytest

from uwgen.cli import main
from uwgen.security.keys import SecurityError, key_id, read_key_file, sender_key


def test_keygen_writes_an_owner_only_key(tmp_path, capsys):
    path = tmp_path / "keys" / "net.key"
    assert main(["keygen", str(path)]) == 0
    assert path.stat().st_mode & 0o777 == 0o600
    key = read_key_file(path)
    assert len(key) == 32
    assert "0600" in capsys.readouterr().out


def test_keygen_refuses_to_overwrite_without_force(tmp_path, capsys):
    path = tmp_path / "net.key"
    assert main(["keygen", str(path)]) == 0
    first = read_key_file(path)
    assert main(["keygen", str(path)]) == 2
    assert "exists" in capsys.readouterr().err and read_key_file(path) == first
    assert main(["keygen", str(path), "--force"]) == 0
    assert read_key_file(path) != first and path.stat().st_mode & 0o777 == 0o600


def test_keygen_is_owner_only_whatever_the_umask(tmp_path):
    old = os.umask(0)
    try:
        assert main(["keygen", str(tmp_path / "k")]) == 0
    finally:
        os.umask(old)
    assert (tmp_path / "k").stat().st_mode & 0o777 == 0o600


def test_a_key_readable_by_others_is_refused(tmp_path):
    path = tmp_path / "net.key"
    main(["keygen", str(path)])
    path.chmod(0o644)
    with pytest.raises(SecurityError, match="chmod 600"):
        read_key_file(path)


@pytest.mark.parametrize("text,why", [("", "one line"), ("zz" * 32, "not a hex digit"),
                                      ("ab" * 16, "16 bytes")])
def test_malformed_keys_are_refused(tmp_path, text, why):
    path = tmp_path / "bad.key"
    path.write_text(text + "\n")
    path.chmod(0o600)
    with pytest.raises(SecurityError, match=why):
        read_key_file(path)


def test_a_missing_key_says_how_to_make_one(tmp_path):
    with pytest.raises(SecurityError, match="uwgen keygen"):
        read_key_file(tmp_path / "nope.key")


def test_every_sender_and_network_has_its_own_key():
    master = bytes(32)
    keys = {sender_key(master, net, s) for net in ("a", "b") for s in range(16)}
    assert len(keys) == 32 and all(len(k) == 16 for k in keys)
    assert key_id(master, "a") != key_id(master, "b")
