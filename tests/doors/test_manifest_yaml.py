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

from .helpers import SAMPLES, bounded, cli, examples

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


@pytest.mark.parametrize("key", ["ttl: 2.0", "rate: 5", "period: 0.2", "timeout: 10",
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


@settings(max_examples=examples(100), deadline=10_000,
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
from uwgen.idl.loader import InterfaceLibrary
from uwgen.manifest.loader import ManifestError, load_manifest
for name in sys.argv[1:]:
    try:
        load_manifest(Path(name), InterfaceLibrary([], installed=False))
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


@pytest.mark.parametrize("change, says", [
    (("id: 4\n", "id: 5\n"), "id 5 of topic /turtle1/pose is already used"),
    (("type: geometry_msgs/msg/Twist", "type: geometry_msgs/msg/Twisty"), "Twisty"),
    (("publisher: surface", "publisher: nobody"), "nobody"),
])
def test_emulate_refuses_what_build_refuses_at_the_same_place(tmp_path, capsys, change, says):
    path = tmp_path / "uwgen.yaml"
    path.write_text(DEMO.replace(*change, 1))
    (tmp_path / "turtlesim").symlink_to(SAMPLES / "turtlesim")     # the interfaces beside it
    outs = []
    for argv in (["build", "-m", path, "-o", tmp_path / "out"], ["emulate", "-m", path, "--duration", "0.05"]):
        rc, out = cli(capsys, *argv)
        assert rc == 2 and says in out, (argv, out)
        outs.append(re.findall(rf"{re.escape(str(path))}:\d+:\d+", out))
    assert outs[0] == outs[1]


# YAML 1.1 (what PyYAML reads) and 1.2 disagree on these; each was taken without a word
# (`max: 1:30` became 90). (spelling, what it must not be read as silently, the advice)
SURPRISES = [("1:30", "base-60", "write 90"), ("1_000", "'_'", "write 1000"), ("+5", "'+' sign", "write 5"),
             ("017", "octal in YAML 1.1 (15)", "write 15 or 17"), ("0b11", "binary", "write 3"),
             ("0o17", "octal in YAML 1.2", "write 15"), ("1:30.5", "base-60", "write 90.5")]


@pytest.mark.parametrize("spelling, what, advice", SURPRISES)
def test_every_number_spelled_the_yaml_11_way_is_a_located_error(tmp_path, lib, spelling, what, advice):
    path = tmp_path / "uwgen.yaml"
    for start, end, line, key in numbers(DEMO):
        path.write_text(DEMO[:start] + spelling + DEMO[end:])
        errors = load_error(path, lib)
        assert any(e.where.line == line and what in str(e) and advice in str(e) for e in errors), \
            (key, line, [str(e) for e in errors])


def test_hexadecimal_and_quoted_text_are_not_surprises(tmp_path, lib):
    path = tmp_path / "uwgen.yaml"
    path.write_text(DEMO.replace("id: 4\n", "id: 0x4\n", 1))
    assert load_manifest(path, lib).topics[0].id == 4


FOUR_MISTAKES = """\
network: four
colour: blue
sides:
  a: {port: 5000}
  b: {port: 5001, sender_id: 16}
security: {mode: sign, key_file: k.key}
topics:
  - {name: /x, id: 3, type: std_msgs/msg/String, publisher: a, rat: 5}
  - {name: /y, id: 4, type: std_msgs/msg/String, publisher: a, rate: -1}
  - {name: /z, id: 3, type: std_msgs/msg/String, publisher: b}
"""


def test_a_manifests_structural_value_and_id_mistakes_come_in_one_pass(tmp_path, capsys):
    path = tmp_path / "uwgen.yaml"
    path.write_text(FOUR_MISTAKES)
    rc, out = cli(capsys, "build", "-m", path, "-o", tmp_path / "out")
    assert rc == 2, out
    located = re.findall(rf"{re.escape(str(path))}:(\d+):\d+: (.*)", out)
    assert [(int(line), says.split(" ")[0:3]) for line, says in located] == [
        (2, ["unknown", "key", "'colour'"]), (5, ["sender_id", "of", "side"]),
        (8, ["unknown", "key", "'rat'"]), (9, ["rate", "of", "topic"]), (10, ["id", "3", "of"])], out
    assert "5 errors" in out
    # nothing that only follows from them: side b's wrong sender_id is not also "missing"
    assert "needs a sender_id" not in out


def test_a_misspelled_key_is_reported_once_not_again_as_what_it_left_out(tmp_path, lib):
    path = tmp_path / "uwgen.yaml"
    spec = "linear.x: {min: -2, max: 2, precision: 2, out_of_range: clamp}"
    assert spec in DEMO
    path.write_text(DEMO.replace(spec, "linear.x: {minimum: -2}", 1))   # and so "says nothing"
    errors = load_error(path, lib)
    assert len(errors) == 1 and "unknown key" in str(errors[0]), [str(e) for e in errors]
