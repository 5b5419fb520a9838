"""The key file door: any content and any name (a special file, a symlink loop, a name of
5 000 characters) gives the key or a SecurityError naming the file, at once; never another
exception, never a read that does not end."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.security.keys import MASTER_KEY_BYTES, SecurityError, read_key_file

from .helpers import bounded, examples

FUZZ = settings(max_examples=examples(200), deadline=10_000,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
HEX = "0123456789abcdefABCDEF"


def test_a_key_file_of_one_line_of_hex_digits_is_read(tmp_path):
    path = tmp_path / "net.key"
    path.write_text("# a comment\n" + "ab" * MASTER_KEY_BYTES + "\n")
    os.chmod(path, 0o600)
    assert read_key_file(path) == bytes([0xAB]) * MASTER_KEY_BYTES


@FUZZ
@given(st.one_of(st.binary(max_size=200),
                 st.text(alphabet=HEX + "#\n \t\r\x00é", max_size=120),
                 st.text(alphabet=HEX, min_size=2 * MASTER_KEY_BYTES - 2, max_size=2 * MASTER_KEY_BYTES + 2),
                 st.just("f" * 100_000)))
def test_any_key_file_content_gives_the_key_or_an_error_naming_the_file(tmp_path, data):
    path = tmp_path / "net.key"
    path.write_bytes(data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data)
    os.chmod(path, 0o600)
    try:
        key = read_key_file(path)
    except SecurityError as error:
        assert str(path) in str(error) and len(str(error)) < 1000
    else:
        assert len(key) == MASTER_KEY_BYTES


# Each special file is read in a child process that must end within the deadline: before
# the key file was opened non-blocking and its kind checked first, /dev/zero and
# /dev/urandom were read forever and a FIFO without a writer blocked the open.
SPECIAL = """
import os, sys
from uwgen.security.keys import SecurityError, read_key_file
for path in sys.argv[1:]:
    try:
        read_key_file(path)
        print("read", path)
    except SecurityError as exc:
        print(exc)
"""


def test_special_files_behind_a_key_file_name_are_refused_at_once(tmp_path):
    names = {"zero": "/dev/zero", "urandom": "/dev/urandom", "null": "/dev/null", "folder": str(tmp_path)}
    for name, target in names.items():
        os.symlink(target, tmp_path / f"{name}.key")
    os.mkfifo(tmp_path / "fifo.key", 0o600)
    os.symlink(tmp_path / "loop-b.key", tmp_path / "loop-a.key")
    os.symlink(tmp_path / "loop-a.key", tmp_path / "loop-b.key")
    paths = [tmp_path / f"{n}.key" for n in (*names, "fifo", "loop-a")]
    res = bounded(SPECIAL + "\n", seconds=20, argv=[str(p) for p in paths])
    lines = res.stdout.splitlines()
    assert res.returncode == 0 and len(lines) == len(paths), res.stdout + res.stderr
    says = dict(zip((*names, "fifo", "loop-a"), lines))
    assert "(a symlink to /dev/zero) is a character device: only a regular file is read" in says["zero"]
    assert "(a symlink to /dev/urandom) is a character device" in says["urandom"]
    assert "is a character device" in says["null"]
    assert "is a folder" in says["folder"]
    assert "is a FIFO (named pipe): only a regular file is read" in says["fifo"]
    assert "is a symlink loop" in says["loop-a"]


def test_a_key_file_that_is_a_symlink_to_a_good_key_is_read(tmp_path):
    real = tmp_path / "secrets" / "net.key"
    real.parent.mkdir()
    real.write_text("cd" * MASTER_KEY_BYTES + "\n")
    os.chmod(real, 0o600)
    os.symlink(real, tmp_path / "net.key")
    assert read_key_file(tmp_path / "net.key") == bytes([0xCD]) * MASTER_KEY_BYTES


def test_a_5000_character_key_file_name_is_a_short_clear_error(tmp_path):
    path = tmp_path / ("k" * 5000)
    with pytest.raises(SecurityError, match="has a name too long for this system") as info:
        read_key_file(path)
    assert len(str(info.value)) < 400 and "(a name of" in str(info.value)


def test_a_key_file_bigger_than_any_key_is_refused_before_it_is_read(tmp_path):
    path = tmp_path / "net.key"
    with open(path, "wb") as f:
        f.truncate(10 * 1024 ** 3)          # 10 GiB of holes: never read
    os.chmod(path, 0o600)
    with pytest.raises(SecurityError, match=r"is 10737418240 bytes long: uwgen reads at most 64 KiB"):
        read_key_file(path)


def test_the_mode_is_checked_before_the_content(tmp_path):
    path = tmp_path / "net.key"
    path.write_bytes(b"\xff" * 10)
    os.chmod(path, 0o644)
    with pytest.raises(SecurityError, match="accessible to others"):
        read_key_file(path)


@pytest.mark.parametrize("digits", [63, 65, 62, 66, 2])
def test_a_key_of_the_wrong_length_says_how_many_digits_it_has(tmp_path, digits):
    path = tmp_path / "net.key"
    path.write_text("# comment\n" + ("a1" * 40)[:digits] + "\n")
    os.chmod(path, 0o600)
    with pytest.raises(SecurityError, match=rf"net.key:2: the key has {digits} hex digits .*a key is one "
                                            rf"line of 64 hex digits \(32 bytes\)"):
        read_key_file(path)


def test_raw_bytes_are_named_by_where_they_are_not_by_the_codec(tmp_path):
    path = tmp_path / "net.key"
    path.write_bytes(b"ab" * 10 + b"\xe9\x00" + b"ab" * 21 + b"\n")
    os.chmod(path, 0o600)
    with pytest.raises(SecurityError) as info:
        read_key_file(path)
    assert "net.key:1:21: the byte 0xe9 is not a hex digit (0-9, a-f)" in str(info.value)
    assert "codec" not in str(info.value) and "decode" not in str(info.value)


def test_an_all_zero_key_is_refused(tmp_path):
    path = tmp_path / "net.key"
    path.write_text("00" * MASTER_KEY_BYTES + "\n")
    os.chmod(path, 0o600)
    with pytest.raises(SecurityError, match="all zeros, a placeholder anyone can guess: refused"):
        read_key_file(path)


def _plan(key_file: str, manifest: Path | None):
    from types import SimpleNamespace
    return SimpleNamespace(security=SimpleNamespace(key_file=key_file), manifest_path=manifest,
                           manifest_source=None)


def test_a_missing_key_says_that_a_tilde_was_expanded_not_taken_from_the_manifests_folder(tmp_path):
    from uwgen.bridge.security import _missing_key, key_path
    from types import SimpleNamespace
    plan, options = _plan("~/nosuch-uwgen-dir/net.key", tmp_path / "uwgen.yaml"), SimpleNamespace(key_file=None)
    path = key_path(plan, options)
    assert path == Path.home() / "nosuch-uwgen-dir" / "net.key"
    says = _missing_key(plan, options, path)
    assert "('~' expanded to the home folder)" in says and "relative" not in says, says


def test_a_missing_relative_key_names_the_folder_it_was_taken_from(tmp_path):
    from uwgen.bridge.security import _missing_key, key_path
    from types import SimpleNamespace
    plan, options = _plan("keys/net.key", tmp_path / "uwgen.yaml"), SimpleNamespace(key_file=None)
    says = _missing_key(plan, options, key_path(plan, options))
    assert f"(taken relative to the manifest's folder {tmp_path})" in says, says


BRIDGE = """
import sys
from uwgen.cli import main
manifest = sys.argv[1]
for key in sys.argv[2:]:
    rc = main(["bridge", "-m", manifest, "--side", "vehicle", "--port", "9", "--key-file", key])
    print(rc, flush=True)
"""


def test_the_bridge_refuses_every_special_key_file_with_exit_2_at_once(tmp_path):
    # Before: a symlink to /dev/zero or a FIFO as --key-file hung the bridge (deaf to Ctrl-C).
    from .helpers import SAMPLES
    os.symlink("/dev/zero", tmp_path / "zero.key")
    os.mkfifo(tmp_path / "fifo.key", 0o600)
    os.symlink(tmp_path / "loop.key", tmp_path / "loop.key")
    keys = [tmp_path / "zero.key", tmp_path / "fifo.key", tmp_path / "loop.key", "/dev/urandom",
            tmp_path / ("k" * 5000), tmp_path]
    res = bounded(BRIDGE, seconds=60, argv=[str(SAMPLES / "uwgen.yaml"), *map(str, keys)])
    assert res.stdout.split() == ["2"] * len(keys), res.stdout + res.stderr[-3000:]
    assert "Traceback" not in res.stderr
    for says in ("(a symlink to /dev/zero) is a character device", "is a FIFO (named pipe)", "is a symlink loop",
                 "/dev/urandom is a character device", "has a name too long for this system", "is a folder"):
        assert says in res.stderr, (says, res.stderr[-3000:])
