"""Recursive and too deeply nested types are refused at build time with file:line errors;
whatever builds also imports (no "too many nested parentheses")."""
from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from uwgen.codegen.emit import Lowering
from uwgen.codegen.emit_common import Constants
from uwgen.codegen.emit_decode import NEST_CHUNK
from uwgen.codegen.generator import plan_build
from uwgen.codegen.render import render_package, write_package
from uwgen.codegen.ir import IRBuilder
from uwgen.codegen.shape import MAX_NESTING
from uwgen.idl.loader import InterfaceLibrary
from uwgen.idl.model import DefinitionError

REPO = Path(__file__).resolve().parents[2]


def write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def chain(n: int) -> dict[str, str]:
    """deep_msgs/N0 contains N1 ... contains N{n-1}, which holds an int32: n levels."""
    files = {f"deep_msgs/msg/N{k}.msg": f"int32 x{k}\nN{k + 1} next\n" for k in range(n - 1)}
    files[f"deep_msgs/msg/N{n - 1}.msg"] = "int32 last\n"
    return files


def build_error(tmp_path: Path, files: dict[str, str]) -> DefinitionError:
    src = write(tmp_path / "src", files)
    with pytest.raises(DefinitionError) as info:
        plan_build([src], installed=False)
    return info.value


@pytest.mark.parametrize("files, where, message", [
    pytest.param({"rec_msgs/msg/Self.msg": "int32 a\nSelf child\n"}, "rec_msgs/msg/Self.msg:2",
                 "recursive message type: rec_msgs/msg/Self -> rec_msgs/msg/Self;", id="direct"),
    pytest.param({"rec_msgs/msg/Tree.msg": "int32 value\nTree[] children\n"}, "rec_msgs/msg/Tree.msg:2",
                 "recursive message type: rec_msgs/msg/Tree -> rec_msgs/msg/Tree (through an array)",
                 id="through-a-sequence"),
    pytest.param({"rec_msgs/msg/A.msg": "B b\n", "rec_msgs/msg/B.msg": "float32 f\nC[<=2] c\n",
                  "rec_msgs/msg/C.msg": "A a\n"}, "rec_msgs/msg/C.msg:1",
                 "recursive message type: rec_msgs/msg/A -> rec_msgs/msg/B -> rec_msgs/msg/C -> rec_msgs/msg/A",
                 id="mutual"),
])
def test_recursive_type_is_a_located_definition_error(tmp_path, files, where, message):
    error = build_error(tmp_path, files)
    assert str(error.where).endswith(where + ":1"), str(error)
    assert message in error.message


def test_a_recursive_type_used_by_a_sound_one_is_reported_at_its_loop(tmp_path):
    error = build_error(tmp_path, {"rec_msgs/msg/Top.msg": "Loop l\n",
                                   "rec_msgs/msg/Loop.msg": "Loop[<=1] again\n"})
    assert str(error.where).endswith("rec_msgs/msg/Loop.msg:1:1")
    assert "rec_msgs/msg/Loop -> rec_msgs/msg/Loop" in error.message


def test_nesting_over_the_limit_is_refused_where_it_crosses_it(tmp_path):
    error = build_error(tmp_path, chain(300))
    limit = MAX_NESTING
    # N0 is level 1, so the field of N{limit-1} that names N{limit} adds level limit + 1.
    assert str(error.where).endswith(f"deep_msgs/msg/N{limit - 1}.msg:2:1"), str(error)
    assert f"deep_msgs/msg/N0 nests messages 300 levels deep, over uwgen's limit of {limit}" in error.message


def test_nesting_through_arrays_counts_too(tmp_path):
    files = {f"deep_msgs/msg/N{k}.msg": f"N{k + 1}[<=2] next\n" for k in range(MAX_NESTING)}
    files[f"deep_msgs/msg/N{MAX_NESTING}.msg"] = "int32 last\n"
    error = build_error(tmp_path, files)
    assert f"{MAX_NESTING + 1} levels deep" in error.message


def test_uwgen_build_of_a_300_deep_chain_exits_with_the_error(tmp_path):
    src = write(tmp_path / "src", chain(300))
    result = subprocess.run([sys.executable, "-m", "uwgen.cli", "build", str(src), "-o", str(tmp_path / "out")],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0
    assert "Traceback" not in result.stderr and "RecursionError" not in result.stderr
    assert f"N{MAX_NESTING - 1}.msg:2:1: deep_msgs/msg/N0 nests messages 300 levels deep" in result.stderr


def test_the_deepest_allowed_chain_builds_imports_and_round_trips(tmp_path):
    src = write(tmp_path / "src", chain(MAX_NESTING))
    plan = plan_build([src], installed=False, package="uwgen_deepest")
    out = tmp_path / "gen" / "uwgen_deepest"
    write_package(render_package(plan), out)
    text = (out / "deep_msgs" / "msg.py").read_text()
    assert "t1 = C.deep_msgs__N" in text                 # built in steps, not one expression
    sys.path.insert(0, str(out.parent))
    try:
        pkg = importlib.import_module("uwgen_deepest")
        codec = pkg.codec("deep_msgs/msg/N0")
        msg = codec.plain_class()()
        node = msg
        for k in range(MAX_NESTING - 1):
            setattr(node, f"x{k}", k - 50)
            node = node.next
        node.last = 123456
        payload = codec.encode(msg, [0, 3])
        back, _ = codec.decode(payload, (0, 3), ros=False)
        assert back == msg
        node = back
        for _ in range(MAX_NESTING - 1):
            node = node.next
        assert node.last == 123456
    finally:
        sys.path.remove(str(out.parent))
        for name in [m for m in sys.modules if m.split(".")[0] == "uwgen_deepest"]:
            del sys.modules[name]


def test_the_emitter_never_nests_expressions_past_the_parser_limit(tmp_path):
    # With the build-time limit lifted, a 300-deep chain still lowers to code Python
    # compiles: nested constructors are split every NEST_CHUNK levels.
    src = write(tmp_path / "src", chain(300))
    lib = InterfaceLibrary([src], installed=False)
    builder = IRBuilder(lib.get, max_nesting=1000)
    ct = builder.codec(lib.get("deep_msgs/msg/N0"), "native")
    fn = Lowering("deep_msgs.msg", Constants(), {ct.key: "deep_msgs.msg"}).decoder(ct)
    source = f"def {fn.name}({fn.args}):\n" + "".join(f"    {line}\n" for line in fn.body)
    compile(source, "<decoder>", "exec")
    assert sum(line.startswith("t") for line in fn.body) == 299 // NEST_CHUNK
    assert max(line.count("(") for line in fn.body) <= NEST_CHUNK + 2


def test_fields_named_like_python_names_still_import_and_construct(tmp_path):
    # ROS allows field names such as `self` and `range`; the plain classes take every
    # field as an __init__ parameter, so they must not collide with what __init__ uses.
    src = write(tmp_path / "src", {
        "nm_msgs/msg/A.msg": "int32 self\nint32 other\n",
        "nm_msgs/msg/B.msg": "int32 x\n",
        "nm_msgs/msg/R.msg": "B[2] range\nint32 type\nint32[] len\nint32 none\n",
    })
    plan = plan_build([src], installed=False, package="uwgen_pynames")
    out = tmp_path / "gen" / "uwgen_pynames"
    write_package(render_package(plan), out)
    sys.path.insert(0, str(out.parent))
    try:
        pkg = importlib.import_module("uwgen_pynames")
        from uwgen_pynames.nm_msgs.msg import A, R
        assert A(self=3, other=4) == A(self=3, other=4) and A().self == 0
        r = R(len=[1, 2])
        assert len(r.range) == 2 and r.range[0].x == 0
        codec = pkg.codec("nm_msgs/msg/R")
        assert codec.decode(codec.encode(r, [0, 3]), (0, 3), ros=False)[0] == r
    finally:
        sys.path.remove(str(out.parent))
        for name in [m for m in sys.modules if m.split(".")[0] == "uwgen_pynames"]:
            del sys.modules[name]
