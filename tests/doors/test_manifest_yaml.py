"""The manifest door (`uwgen build`, `analyze`, `emulate -m`): any text gives a manifest or a
located `file:line:column` error; never a traceback (OverflowError from a 400-digit number,
RecursionError from YAML nested thousands deep), never long."""
from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uwgen.errors import ErrorList
from uwgen.manifest.loader import ManifestError, load_manifest

from .helpers import SAMPLES, bounded, cli

DEMO = (SAMPLES / "uwgen.yaml").read_text()
HUGE = "9" * 400
DEEP = "[" * 3000 + "]" * 3000


def numbers(text: str) -> list[tuple[int, int, int, str]]:
    """(start, end, line, key) of every number in the manifest text, in file order."""
    found = []

    def walk(node, key=""):
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                walk(v, k.value)
        elif isinstance(node, yaml.SequenceNode):
            for v in node.value:
                walk(v, key)
        elif node.tag in ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float"):
            found.append((node.start_mark.index, node.end_mark.index, node.start_mark.line + 1, key))

    walk(yaml.compose(text, Loader=yaml.SafeLoader))
    return found


def errors_of(exc: Exception) -> list[ManifestError]:
    return list(exc.errors) if isinstance(exc, ErrorList) else [exc]


def load_error(path, lib) -> list[ManifestError]:
    with pytest.raises((ManifestError, ErrorList)) as info:
        load_manifest(path, lib)
    return errors_of(info.value)


@pytest.fixture(scope="module")
def lib():
    from uwgen.idl.loader import InterfaceLibrary
    return InterfaceLibrary(folders=[SAMPLES], installed=True)


def test_the_demo_manifest_has_every_kind_of_number():
    keys = {key for *_, key in numbers(DEMO)}
    assert {"ttl", "rate", "period", "timeout", "min", "max", "port", "id", "depth", "priority",
            "precision", "accept_timeout", "result_timeout"} <= keys


@pytest.mark.parametrize("replacement", [HUGE, "-" + HUGE, "1e400", "1e-300", "1e300"])
def test_every_number_out_of_range_is_a_located_error(tmp_path, lib, replacement):
    path = tmp_path / "uwgen.yaml"
    for start, end, line, key in numbers(DEMO):
        path.write_text(DEMO[:start] + replacement + DEMO[end:])
        try:
            load_manifest(path, lib)
        except (ManifestError, ErrorList) as exc:
            errors = errors_of(exc)
            assert any(e.where.path == path and e.where.line == line for e in errors), (key, line, str(exc))
            assert all(len(str(e)) < 400 for e in errors), "the error quotes the whole number"
        else:
            # Only values that are fine where they stand load: a tiny or huge number where
            # the manifest allows any (a field's min or max over a float64 field).
            assert replacement in ("1e-300", "1e300") and key in ("min", "max"), (key, line)


@pytest.mark.parametrize("key", ["ttl: 1.0", "rate: 5", "period: 0.2", "timeout: 10",
                                 "min: -2", "max: 2", "result_timeout: 60"])
def test_a_400_digit_number_is_a_located_error_in_build_and_analyze(tmp_path, capsys, key):
    path = tmp_path / "uwgen.yaml"
    name = key.split(":")[0]
    path.write_text(DEMO.replace(key, f"{name}: {HUGE}", 1))
    line = DEMO[:DEMO.index(key)].count("\n") + 1
    for argv in (["build", "-m", path, "-o", tmp_path / "out", SAMPLES],
                 ["analyze", "-m", path, SAMPLES]):
        rc, out = cli(capsys, *argv)
        assert rc == 2 and re.search(rf"{re.escape(str(path))}:{line}:\d+: ", out), out
        assert "Traceback" not in out and HUGE not in out


def test_a_400_digit_link_period_is_a_located_error_in_emulate(tmp_path, capsys):
    path = tmp_path / "uwgen.yaml"
    path.write_text(DEMO.replace("period: 0.2}", f"period: {HUGE}}}", 1))
    line = DEMO[:DEMO.index("period: 0.2}")].count("\n") + 1
    rc, out = cli(capsys, "emulate", "-m", path, "--duration", "0.1")
    assert rc == 2 and f"{path}:{line}:" in out, out


@pytest.mark.parametrize("where", ["sides: DEEP\n", "topics:\n  - name: DEEP\n", "network: n\nextra: DEEP\n"])
def test_yaml_nested_3000_deep_is_a_located_error_in_build_analyze_and_emulate(tmp_path, capsys, where):
    path = tmp_path / "uwgen.yaml"
    path.write_text(("" if where.startswith("network") else "network: n\n") + where.replace("DEEP", DEEP))
    for argv in (["build", "-m", path, "-o", tmp_path / "out", SAMPLES], ["analyze", "-m", path, SAMPLES],
                 ["emulate", "-m", path, "--duration", "0.1"]):
        rc, out = cli(capsys, *argv)
        assert rc == 2 and re.search(rf"{re.escape(str(path))}:\d+:\d+: .*nested more than 64 levels", out), (argv, out)


def test_a_scenario_nested_3000_deep_is_a_located_error(tmp_path, capsys):
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(f"nodes: {DEEP}\n")
    rc, out = cli(capsys, "emulate", scenario, "--duration", "0.1")
    assert rc == 2 and f"{scenario}:1:" in out and "nested more than 64 levels" in out, out


PIECES = [":", "-", " ", "\n", "{", "}", "[", "]", "'", '"', "#", "0", "256", "-1", "null", "true",
          "fifo", "id", "name", "depth", "&a", "*a", "!!str", "\t", "é", HUGE, "-" + HUGE, "1e400",
          "1e-300", ".inf", ".nan", "0x" + "f" * 40, "[" * 200, "{a: " * 100, "- " * 100]


@st.composite
def mutated_demo(draw):
    text = DEMO
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(text)))
        if draw(st.booleans()):
            text = text[:at] + draw(st.sampled_from(PIECES)) + text[at:]
        else:
            text = text[:at] + text[at + draw(st.integers(1, 12)):]
    return text


@pytest.fixture(scope="module")
def warm(tmp_path_factory, lib):
    """One build and analysis first: the first ones import the generator and its templates,
    which is not what the deadline below is about."""
    out = tmp_path_factory.mktemp("warm")
    from uwgen.cli import main
    main(["build", "-m", str(SAMPLES / "uwgen.yaml"), "-o", str(out / "g"), str(SAMPLES)])
    main(["analyze", "-m", str(SAMPLES / "uwgen.yaml"), str(SAMPLES)])
    return lib


@settings(max_examples=100, deadline=10_000,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(text=mutated_demo())
def test_any_mutated_manifest_loads_or_fails_with_a_located_error(tmp_path, capsys, warm, text):
    lib = warm
    path = tmp_path / "uwgen.yaml"
    path.write_text(text, encoding="utf-8")
    try:
        manifest = load_manifest(path, lib)
    except (ManifestError, ErrorList) as exc:
        for error in errors_of(exc):
            assert error.where is not None and error.where.path == path
            assert 1 <= error.where.line <= text.count("\n") + 2 and error.where.column >= 1
        return
    assert manifest.network and manifest.sides
    # What loads also builds and analyses, or says why (never a traceback: cli() would raise).
    for argv in (["build", "-m", path, "-o", tmp_path / "out", SAMPLES], ["analyze", "-m", path, SAMPLES]):
        rc, out = cli(capsys, *argv)
        assert rc == 0 or (rc in (1, 2) and out.strip()), (argv, rc, out)


# Each name is tried in a child process that must end within the deadline: a manifest read
# with no size limit took /dev/zero to a MemoryError and a FIFO blocked its open forever.
SPECIAL_MANIFESTS = """
import sys
from uwgen.cli import main
for name in sys.argv[1:]:
    for argv in (["build", "-m", name, "-o", "/nonexistent/out"], ["analyze", "-m", name],
                 ["emulate", "-m", name, "--duration", "0.05"], ["rmw-config", "export", "-m", name]):
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code
        print(rc, argv[0], flush=True)
"""


def special_names(tmp_path):
    """name -> path of every kind of file a manifest's name must not lead to."""
    os.symlink("/dev/zero", tmp_path / "zero.yaml")
    os.mkfifo(tmp_path / "fifo.yaml")
    os.symlink(tmp_path / "b.yaml", tmp_path / "loop.yaml")
    os.symlink(tmp_path / "loop.yaml", tmp_path / "b.yaml")
    return {"zero": tmp_path / "zero.yaml", "urandom": Path("/dev/urandom"), "fifo": tmp_path / "fifo.yaml",
            "loop": tmp_path / "loop.yaml", "long": tmp_path / ("m" * 5000)}


def test_special_files_and_long_names_as_a_manifest_are_usage_errors_in_every_command(tmp_path):
    names = special_names(tmp_path)
    res = bounded(SPECIAL_MANIFESTS, seconds=60, argv=[str(p) for p in names.values()])
    assert "Traceback" not in res.stderr, res.stderr[-3000:]
    assert res.stdout.split() == ["2", "build", "2", "analyze", "2", "emulate", "2", "rmw-config"] * len(names), res.stdout
    for says in ("zero.yaml (a symlink to /dev/zero) is a character device: only a regular file is read",
                 "/dev/urandom is a character device", "fifo.yaml is a FIFO (named pipe)",
                 "loop.yaml is a symlink loop", "(a name of 5", "has a name too long for this system"):
        assert res.stderr.count(says) == 4, (says, res.stderr[-3000:])


LOADER = """
import sys
from pathlib import Path
from uwgen.manifest.loader import ManifestError, load_sides
for name in sys.argv[1:]:
    try:
        load_sides(Path(name))
    except ManifestError as exc:
        print(exc, flush=True)
"""


def test_the_manifest_loader_reads_only_a_regular_file_of_at_most_a_mebibyte(tmp_path):
    names = special_names(tmp_path)
    big = tmp_path / "big.yaml"
    big.write_text("network: n\n" + "#" * (1024 ** 2) + "\n")
    res = bounded(LOADER, seconds=30, argv=[str(p) for p in (*names.values(), big)])
    lines = res.stdout.splitlines()
    assert res.returncode == 0 and len(lines) == len(names) + 1, res.stdout + res.stderr
    assert "is a character device" in lines[0] and "is a FIFO" in lines[2] and "symlink loop" in lines[3]
    assert lines[-1].endswith("big.yaml is 1048588 bytes long: uwgen reads at most 1 MiB")
