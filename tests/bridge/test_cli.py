"""`uwgen bridge` and the generated bridge modules: arguments and errors."""
import subprocess
import sys
from pathlib import Path

import pytest

from uwgen.bridge.plan import BridgePlan, PlanError
from uwgen.cli import main as uwgen_main
from uwgen.commands.bridge import package_name

from .fakes import FakeTopicCodec, fake_package

ROOT = Path(__file__).resolve().parents[2]


def test_unknown_side_exits_2_and_names_the_sides(capsys):
    rc = uwgen_main(["bridge", "-m", str(ROOT / "msg_samples" / "uwgen.yaml"), "--side", "boat",
                     "--package-dir", str(ROOT / "generated")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "side 'boat'" in err and "surface" in err and "vehicle" in err


def test_missing_generated_package_exits_2(tmp_path, capsys):
    manifest = tmp_path / "m.yaml"
    manifest.write_text("network: nowhere\n")
    rc = uwgen_main(["bridge", "-m", str(manifest), "--side", "a", "--package-dir", str(tmp_path)])
    assert rc == 2
    assert "uwgen_nowhere" in capsys.readouterr().err


def test_manifest_that_is_not_yaml_is_located(tmp_path):
    manifest = tmp_path / "m.yaml"
    manifest.write_text("network: [unclosed\n")
    with pytest.raises(PlanError, match=r"m\.yaml:\d+:\d+: not valid YAML"):
        package_name(manifest)


def test_package_name_comes_from_the_manifest(tmp_path):
    manifest = tmp_path / "m.yaml"
    manifest.write_text("network: demo\n")
    assert package_name(manifest) == "uwgen_demo"
    manifest.write_text("network: demo\npackage: my_pkg\n")
    assert package_name(manifest) == "my_pkg"


def test_flags_override_the_manifest_side_entry():
    plan = BridgePlan.from_package(fake_package([FakeTopicCodec(4, "/c", None, "surface")]), "vehicle")
    assert plan.options().port == 4001
    opts = plan.options(port=5001, host="127.0.0.1", max_read_length=32, period=0.5)
    assert (opts.port, opts.link.max_read_length, opts.link.period) == (5001, 32, 0.5)
    with pytest.raises(PlanError, match="4096"):
        plan.options(max_read_length=5000)
    with pytest.raises(PlanError, match="timeout reply"):
        plan.options(timeout_reply="maybe")


def test_generated_bridge_module_runs_directly():
    if not (ROOT / "generated" / "uwgen_demo" / "bridge_vehicle.py").exists():
        pytest.skip("generated/uwgen_demo has no bridge modules yet")
    res = subprocess.run([sys.executable, "-m", "uwgen_demo.bridge_vehicle", "--help"],
                         cwd=ROOT / "generated", capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert "--port" in res.stdout and "side vehicle" in res.stdout
    res = subprocess.run([sys.executable, "-m", "uwgen_demo.bridge_vehicle", "--port", "0"],
                         cwd=ROOT / "generated", capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and "not a TCP port" in res.stderr
