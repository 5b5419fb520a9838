"""A broken manifest reports all its errors in one pass, each at its line:column, and an
unknown type gets a "did you mean". Run with the real `uwgen build` command."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from uwgen.manifest.loader import ManifestErrors, load_manifest

from .helpers import library

UWGEN = Path(sys.executable).parent / "uwgen"
FOUR = """\
network: four
sides:
  surface: {port: 70000}
  vehicle: {port: 4001}
topics:
  - {name: /a, id: 4, type: geometry_msgs/msg/Twst, publisher: surface}
  - {name: /b, id: 5, type: std_msgs/msg/String, publisher: boat}
  - {name: /c, id: 6, type: std_msgs/msg/String, publisher: vehicle, rate: fast}
"""


def build(tmp_path, text):
    (tmp_path / "uwgen.yaml").write_text(text)
    return subprocess.run([str(UWGEN), "build", "-m", "uwgen.yaml", "--check"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)


def test_four_errors_are_reported_in_one_pass(tmp_path):
    res = build(tmp_path, FOUR)
    assert res.returncode == 2
    lines = [line for line in res.stderr.splitlines() if "uwgen.yaml:" in line]
    assert [line.split("uwgen.yaml:")[1].split(":")[0] for line in lines] == ["3", "6", "7", "8"], res.stderr
    assert "port of side 'surface'" in lines[0]
    assert "Twst" in lines[1] and "boat" in lines[2] and "rate of topic /c" in lines[3]
    assert "4 errors" in res.stderr


def test_an_unknown_type_gets_a_did_you_mean(tmp_path):
    res = build(tmp_path, FOUR)
    assert "did you mean geometry_msgs/msg/Twist?" in res.stderr


def test_a_type_in_the_wrong_package_is_found_in_the_right_one(tmp_path):
    res = build(tmp_path, FOUR.replace("geometry_msgs/msg/Twst", "std_msgs/msg/Twist"))
    assert "did you mean geometry_msgs/msg/Twist?" in res.stderr


def test_one_entry_with_two_mistakes_reports_both(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("network: two\nsides:\n  surface: {port: 4000}\n  vehicle: {port: 4001}\n"
                    "topics:\n  - {name: /a, id: 4, type: std_msgs/msg/Strin, publisher: boat}\n")
    try:
        load_manifest(path, library())
    except ManifestErrors as exc:
        assert [str(e.where).rsplit(":", 2)[1:] for e in exc.errors] == [["6", "29"], ["6", "60"]]
    else:
        raise AssertionError("no error")
