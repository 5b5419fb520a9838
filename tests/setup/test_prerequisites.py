"""run.py checks the prerequisites the README states before setting anything up."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import run
from uwgen.typesupport import BUILD_TOOLS

ROOT = Path(__file__).resolve().parents[2]


def test_run_py_checks_the_tools_uwgen_builds_type_support_with():
    assert run.BUILD_TOOLS == BUILD_TOOLS


def test_the_readme_states_the_prerequisites():
    text = (ROOT / "README.md").read_text()
    assert "apt-get install cmake g++ make" in text and "Python 3.11" in text


def test_a_missing_tool_stops_run_py_up_front_with_what_to_install(tmp_path):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "python3").symlink_to(sys.executable)   # a machine with Python and nothing else
    env = {**os.environ, "PATH": str(bin_dir)}
    for job in ("demo", "test"):
        res = subprocess.run([sys.executable, str(ROOT / "run.py"), job], env=env, cwd=tmp_path,
                             capture_output=True, text=True, timeout=60)
        assert res.returncode == 2, res.stdout + res.stderr
        assert "cmake, c++, cc, make" in res.stderr and "apt-get install cmake g++ make" in res.stderr
        assert "[run.py]" not in res.stdout     # nothing was set up or run
