"""The bridge and the build agree: `uwgen bridge -m` finds the package the build wrote
next to the manifest's project and refuses one built from other files."""
import sys
from pathlib import Path

import pytest

from uwgen.cli import main as uwgen_main

MANIFEST = """\
network: agree
sides:
  surface: {port: 4000}
  vehicle: {port: 4001}
topics:
  - {name: /note, id: 4, type: agree_msgs/msg/Note, publisher: vehicle}
  - {name: /cmd, id: 5, type: geometry_msgs/msg/Twist, publisher: surface}
"""


@pytest.fixture
def project(tmp_path, monkeypatch):
    """proj/interfaces/{agree_msgs/msg/Note.msg, uwgen.yaml}, built from proj."""
    proj = tmp_path / "proj"
    (proj / "interfaces" / "agree_msgs" / "msg").mkdir(parents=True)
    (proj / "interfaces" / "agree_msgs" / "msg" / "Note.msg").write_text("string text\n")
    (proj / "interfaces" / "uwgen.yaml").write_text(MANIFEST)
    monkeypatch.chdir(proj)
    assert uwgen_main(["build", "interfaces"]) == 0
    assert (proj / "generated" / "uwgen_agree" / "__init__.py").is_file()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)   # the bridge runs from another folder
    return proj


def bridge(manifest, capsys, side="nowhere"):
    rc = uwgen_main(["bridge", "-m", str(manifest), "--side", side])
    return rc, capsys.readouterr().err


def test_bridge_finds_generated_next_to_the_manifests_project(project, capsys):
    rc, err = bridge(project / "interfaces" / "uwgen.yaml", capsys)
    # Found and fresh: what stops it is the unknown side, checked after both.
    assert rc == 2 and "side 'nowhere'" in err and "stale" not in err


def test_edited_manifest_is_refused_with_the_command_that_rebuilds(project, capsys):
    manifest = project / "interfaces" / "uwgen.yaml"
    manifest.write_text(MANIFEST.replace("id: 5", "id: 4"))   # now even an invalid one
    rc, err = bridge(manifest, capsys)
    assert rc == 2
    assert "stale" in err and f"{manifest} changed" in err
    assert f"cd {project} && uwgen build interfaces" in err


def test_edited_definition_is_refused(project, capsys):
    (project / "interfaces" / "agree_msgs" / "msg" / "Note.msg").write_text("string text\nuint8 level\n")
    rc, err = bridge(project / "interfaces" / "uwgen.yaml", capsys)
    assert rc == 2 and "Note.msg changed" in err and "uwgen build interfaces" in err


def test_rebuilt_package_is_taken_again(project, capsys, monkeypatch):
    manifest = project / "interfaces" / "uwgen.yaml"
    manifest.write_text(MANIFEST.replace("port: 4001", "port: 4002"))
    assert bridge(manifest, capsys)[0] == 2
    monkeypatch.chdir(project)
    assert uwgen_main(["build", "interfaces"]) == 0
    for name in [m for m in sys.modules if m.startswith("uwgen_agree")]:
        del sys.modules[name]    # a bridge is a new process; this test is one process
    rc, err = bridge(manifest, capsys)
    assert "stale" not in err and "side 'nowhere'" in err


def test_missing_package_names_the_places_looked_at(tmp_path, capsys, monkeypatch):
    (tmp_path / "a" / "b").mkdir(parents=True)
    manifest = tmp_path / "a" / "b" / "uwgen.yaml"
    manifest.write_text(MANIFEST)
    monkeypatch.chdir(tmp_path)
    rc, err = bridge(manifest, capsys)
    assert rc == 2
    assert "'uwgen_agree' not found" in err
    assert str(tmp_path / "a" / "b" / "generated") in err and str(tmp_path / "a" / "generated") in err
    assert f"uwgen build -m {manifest}" in err


def test_build_from_a_manifest_of_installed_types_alone(tmp_path, monkeypatch):
    manifest = tmp_path / "net.yaml"
    manifest.write_text(MANIFEST.replace("type: agree_msgs/msg/Note", "type: std_msgs/msg/String"))
    monkeypatch.chdir(tmp_path)
    assert uwgen_main(["build", "-m", "net.yaml"]) == 0
    init = (tmp_path / "generated" / "uwgen_agree" / "__init__.py").read_text()
    assert '"command": "uwgen build -m net.yaml"' in init and "std_msgs/msg/String" in init


def test_bare_build_outside_a_project_says_what_to_do(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert uwgen_main(["build"]) == 2
    err = capsys.readouterr().err
    assert "uwgen build DIR" in err and "uwgen build -m MANIFEST" in err and "[tool.uwgen]" in err


def test_check_hint_repeats_the_command_that_was_checked(project, capsys, monkeypatch):
    monkeypatch.chdir(project)
    (project / "interfaces" / "uwgen.yaml").write_text(MANIFEST.replace("4001", "4003"))
    assert uwgen_main(["build", "interfaces", "--check"]) == 1
    err = capsys.readouterr().err
    assert "run `uwgen build interfaces` (in" in err


def test_every_broken_manifest_entry_is_reported(tmp_path, capsys, monkeypatch):
    broken = MANIFEST + "".join(
        f"  - {{name: /t{k}, id: {10 + k}, type: std_msgs/msg/Nope{k}, publisher: vehicle}}\n"
        for k in range(3))
    (tmp_path / "m.yaml").write_text(broken.replace("agree_msgs/msg/Note", "std_msgs/msg/String"))
    monkeypatch.chdir(tmp_path)
    assert uwgen_main(["build", "-m", "m.yaml"]) == 2
    err = capsys.readouterr().err
    for k in range(3):
        assert f"m.yaml:{8 + k}:" in err and f"Nope{k}" in err
    assert "3 errors" in err


def test_errors_beyond_the_limit_are_counted(tmp_path, capsys, monkeypatch):
    broken = MANIFEST.replace("agree_msgs/msg/Note", "std_msgs/msg/String") + "".join(
        f"  - {{name: /t{k}, id: {10 + k}, type: std_msgs/msg/Nope, publisher: vehicle}}\n"
        for k in range(25))
    (tmp_path / "m.yaml").write_text(broken)
    monkeypatch.chdir(tmp_path)
    assert uwgen_main(["build", "-m", "m.yaml"]) == 2
    err = capsys.readouterr().err
    assert err.count("unknown type") == 20 and "25 errors (the first 20 shown)" in err


def test_every_broken_definition_is_reported(tmp_path, capsys):
    pkg = tmp_path / "bad_msgs" / "msg"
    pkg.mkdir(parents=True)
    (pkg / "A.msg").write_text("int33 x\n")
    (pkg / "B.msg").write_text("float64 y\nstring[ z\n")
    (pkg / "C.msg").write_text("bool ok\n")
    assert uwgen_main(["build", str(tmp_path), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "A.msg:1:" in err and "B.msg:2:" in err and "C.msg" not in err and "2 errors" in err


def test_a_broken_definition_the_manifest_names_is_reported_once(tmp_path, capsys, monkeypatch):
    (tmp_path / "agree_msgs" / "msg").mkdir(parents=True)
    (tmp_path / "agree_msgs" / "msg" / "Note.msg").write_text("int33 x\n")
    (tmp_path / "uwgen.yaml").write_text(MANIFEST)
    monkeypatch.chdir(tmp_path)
    assert uwgen_main(["build", "."]) == 2
    err = capsys.readouterr().err
    assert err.count("Note.msg:1:") == 1, err


def test_generated_bridge_module_checks_itself_in_its_project(project):
    import subprocess
    root = Path(__file__).resolve().parents[2]
    env = {**__import__("os").environ, "PYTHONPATH": f"{project / 'generated'}:{root}"}
    run = lambda: subprocess.run([sys.executable, "-m", "uwgen_agree.bridge_vehicle", "--port", "0"],
                                 cwd=project, capture_output=True, text=True, timeout=60, env=env)
    fresh = run()
    assert fresh.returncode == 2 and "not a TCP port" in fresh.stderr   # got past the check
    (project / "interfaces" / "uwgen.yaml").write_text(MANIFEST.replace("id: 5", "id: 6"))
    stale = run()
    assert stale.returncode == 2 and "stale" in stale.stderr and "uwgen build interfaces" in stale.stderr
