"""Schema fingerprints: one per manifest id, changed by anything that changes its bytes."""
from __future__ import annotations

import dataclasses
import importlib
import sys
import textwrap
from fractions import Fraction
from pathlib import Path

import pytest

from uwgen.codegen.fingerprint import FINGERPRINT_BYTES, canonical, digest
from uwgen.codegen.generator import plan_build
from uwgen.codegen.render import render_package, write_package

BASE_MSGS = {
    "fp_msgs/msg/Inner.msg": "float64 a\nint32[<=4] b\n",
    "fp_msgs/msg/Outer.msg": "Inner inner\nInner[<=3] more\nstring name\n",
    "fp_msgs/msg/Other.msg": "uint8 level\n",
    "fp_msgs/srv/Ask.srv": "int32 q\n---\nbool ok\n",
}
BASE_MANIFEST = """
network: fp
schema_id: 240
sides:
  a: {port: 4000}
  b: {port: 4001}
topics:
  - {name: /outer, id: 3, type: fp_msgs/msg/Outer, publisher: a}
  - {name: /other, id: 4, type: fp_msgs/msg/Other, publisher: b}
services:
  - {name: /ask, id: 5, type: fp_msgs/srv/Ask, server: b}
"""


def fingerprints(tmp_path: Path, msgs: dict[str, str] | None = None, manifest: str = BASE_MANIFEST,
                 name: str = "x"):
    root = tmp_path / name
    for rel, text in (msgs or BASE_MSGS).items():
        path = root / "src" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    (root / "uwgen.yaml").write_text(textwrap.dedent(manifest))
    plan = plan_build([root / "src"], manifest_path=root / "uwgen.yaml", installed=False)
    return plan


def changed(tmp_path, msgs=None, manifest=BASE_MANIFEST):
    """Which ids' fingerprints differ from the base build, and whether the digest did."""
    base = fingerprints(tmp_path, name="base")
    other = fingerprints(tmp_path, msgs, manifest, name="other")
    assert base.fingerprints.keys() == other.fingerprints.keys()
    ids = {k for k in base.fingerprints if base.fingerprints[k] != other.fingerprints[k]}
    return ids, base.schema_digest != other.schema_digest


def edit(rel: str, text: str) -> dict[str, str]:
    return {**BASE_MSGS, rel: text}


def test_fingerprints_are_fixed_length_and_deterministic(tmp_path):
    one = fingerprints(tmp_path, name="one")
    two = fingerprints(tmp_path, name="two")
    assert one.fingerprints == two.fingerprints and one.schema_digest == two.schema_digest
    assert set(one.fingerprints) == {("topic", 3), ("topic", 4), ("service", 5)}
    assert all(len(fp) == FINGERPRINT_BYTES for fp in one.fingerprints.values())
    assert len(set(one.fingerprints.values())) == 3


@pytest.mark.parametrize("msgs, manifest, expect", [
    pytest.param(edit("fp_msgs/msg/Inner.msg", "float32 a\nint32[<=4] b\n"), BASE_MANIFEST, {("topic", 3)},
                 id="field-type-of-inlined-type"),
    pytest.param(edit("fp_msgs/msg/Inner.msg", "float64 a\nint32[<=5] b\n"), BASE_MANIFEST, {("topic", 3)},
                 id="array-bound"),
    pytest.param(edit("fp_msgs/msg/Inner.msg", "float64 alpha\nint32[<=4] b\n"), BASE_MANIFEST, {("topic", 3)},
                 id="field-name"),
    pytest.param(edit("fp_msgs/msg/Outer.msg", "Inner inner\nInner[<=3] more\nstring<=8 name\n"), BASE_MANIFEST,
                 {("topic", 3)}, id="string-bound"),
    pytest.param(edit("fp_msgs/msg/Other.msg", "uint16 level\n"), BASE_MANIFEST, {("topic", 4)},
                 id="other-topic-type"),
    pytest.param(edit("fp_msgs/srv/Ask.srv", "int32 q\n---\nbool ok\nstring why\n"), BASE_MANIFEST,
                 {("service", 5)}, id="service-response-only"),
    pytest.param(edit("fp_msgs/srv/Ask.srv", "int64 q\n---\nbool ok\n"), BASE_MANIFEST,
                 {("service", 5)}, id="service-request-only"),
    pytest.param(None, BASE_MANIFEST.replace("id: 4, type: fp_msgs/msg/Other, publisher: b",
                                             "id: 4, type: fp_msgs/msg/Other, publisher: b, profile: packed"),
                 {("topic", 4)}, id="profile"),
    # an rmw_desert entry keeps the whole link on wire format 1: every id changes, /outer's
    # too (the service goes rmw_desert with it: a native command beside it is refused)
    pytest.param(None, BASE_MANIFEST.replace("id: 4, type: fp_msgs/msg/Other, publisher: b",
                                             "id: 4, type: fp_msgs/msg/Other, publisher: b, profile: rmw_desert")
                 .replace("server: b}", "server: b, profile: rmw_desert}"),
                 {("topic", 3), ("topic", 4), ("service", 5)}, id="wire-format"),
    pytest.param(None, BASE_MANIFEST.replace("/other, id: 4, type: fp_msgs/msg/Other",
                                             "/other, id: 4, type: fp_msgs/msg/Inner"),
                 {("topic", 4)}, id="type-of-id"),
])
def test_one_change_changes_that_id_only(tmp_path, msgs, manifest, expect):
    ids, digest_changed = changed(tmp_path, msgs, manifest)
    assert ids == expect
    assert digest_changed


def test_element_type_of_a_message_array_is_hashed(tmp_path):
    # Outer.more is Inner[<=3]: Inner's codec is referenced by key, not inlined.
    msgs = {**BASE_MSGS, "fp_msgs/msg/Outer.msg": "Other[<=3] more\n",
            "fp_msgs/msg/Other.msg": "uint8 level\n"}
    msgs2 = {**msgs, "fp_msgs/msg/Other.msg": "int8 level\n"}
    a = fingerprints(tmp_path, msgs, name="a")
    b = fingerprints(tmp_path, msgs2, name="b")
    assert a.fingerprints[("topic", 3)] != b.fingerprints[("topic", 3)]


def test_what_does_not_touch_the_bytes_keeps_the_fingerprints(tmp_path):
    # Link policy, QoS, ROS name, sides and comments do not change how an id is encoded.
    manifest = BASE_MANIFEST.replace("{name: /outer, id: 3, type: fp_msgs/msg/Outer, publisher: a}",
                                     "{name: /renamed, id: 3, type: fp_msgs/msg/Outer, publisher: b, rate: 2,"
                                     " queue: fifo, depth: 3}")
    msgs = edit("fp_msgs/msg/Other.msg", "# a comment\nuint8 level  # percent\n")
    ids, digest_changed = changed(tmp_path, msgs, manifest)
    assert ids == set() and not digest_changed


def test_moving_a_type_to_another_id_changes_both(tmp_path):
    manifest = BASE_MANIFEST.replace("id: 3, type", "id: 6, type")
    base = fingerprints(tmp_path, name="base")
    other = fingerprints(tmp_path, manifest=manifest, name="other")
    assert ("topic", 6) in other.fingerprints and ("topic", 3) not in other.fingerprints
    assert other.fingerprints[("topic", 6)] != base.fingerprints[("topic", 3)]
    assert other.fingerprints[("topic", 4)] == base.fingerprints[("topic", 4)]


def test_generated_codecs_carry_their_fingerprint(tmp_path):
    plan = fingerprints(tmp_path, name="gen")
    out = tmp_path / "pkgs" / "uwgen_fp"
    write_package(render_package(plan), out)
    sys.path.insert(0, str(out.parent))
    try:
        pkg = importlib.import_module("uwgen_fp")
        assert pkg.TOPICS[3].fingerprint == plan.fingerprints[("topic", 3)]
        assert pkg.TOPICS[4].fingerprint == plan.fingerprints[("topic", 4)]
        assert pkg.SERVICES[5].fingerprint == plan.fingerprints[("service", 5)]
        assert pkg.SCHEMA_DIGEST == plan.schema_digest and len(pkg.SCHEMA_DIGEST) == FINGERPRINT_BYTES
        assert pkg.MANIFEST.schema_id == 240 and pkg.MANIFEST.schema_period == 600.0
    finally:
        sys.path.remove(str(out.parent))
        for name in [m for m in sys.modules if m == "uwgen_fp" or m.startswith("uwgen_fp.")]:
            del sys.modules[name]


# --- the canonical form, generically over IR dataclasses ------------------------------

@dataclasses.dataclass(frozen=True)
class FutureNode:
    """Stands for an IR node class another branch adds later (never named by uwgen)."""
    lo: Fraction
    step: Fraction
    kind: str = "future"


def test_any_dataclass_field_reaches_the_hash():
    a = canonical(FutureNode(Fraction(-10), Fraction(1, 10)))
    b = canonical(FutureNode(Fraction(-10), Fraction(1, 100)))
    assert a["@"] == "FutureNode" and a["step"] == {"@": "Fraction", "n": 1, "d": 10}
    assert digest(a) != digest(b)


def test_a_value_without_canonical_form_is_refused():
    with pytest.raises(TypeError, match="no canonical form for object at .step"):
        canonical(FutureNode(Fraction(1), object()), "")  # type: ignore[arg-type]


def test_same_fingerprints_in_processes_with_different_hash_seeds(tmp_path):
    import os
    import subprocess
    root = tmp_path / "src"
    for rel, text in BASE_MSGS.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    (tmp_path / "uwgen.yaml").write_text(textwrap.dedent(BASE_MANIFEST))
    code = ("import sys; from pathlib import Path; from uwgen.codegen.generator import plan_build; "
            "p = plan_build([Path(sys.argv[1])], manifest_path=Path(sys.argv[2]), installed=False); "
            "print(sorted((k, v.hex()) for k, v in p.fingerprints.items()), p.schema_digest.hex())")
    outs = []
    for seed in ("1", "2"):
        env = dict(os.environ, PYTHONHASHSEED=seed)
        result = subprocess.run([sys.executable, "-c", code, str(root), str(tmp_path / "uwgen.yaml")],
                                capture_output=True, text=True, env=env, timeout=60,
                                cwd=Path(__file__).resolve().parents[2])
        assert result.returncode == 0, result.stderr
        outs.append(result.stdout)
    assert outs[0] == outs[1] and "topic" in outs[0]


def test_fingerprints_cover_the_codecs_the_entries_are_generated_from(tmp_path):
    # A tripwire for codec variants per entry (e.g. field encodings): the codec types a
    # fingerprint hashes are those the generated TopicCodec/ServiceCodec encode with.
    from uwgen.codegen.emit_common import func_name
    from uwgen.codegen.fingerprint import entry_codecs
    from uwgen.codegen.generator import plan_package
    from uwgen.codegen.ir import IRBuilder
    from uwgen.idl.loader import InterfaceLibrary
    from uwgen.manifest.loader import load_manifest

    plan = fingerprints(tmp_path, name="tw")
    lib = InterfaceLibrary([tmp_path / "tw" / "src"], installed=False)
    manifest = load_manifest(tmp_path / "tw" / "uwgen.yaml", lib)
    chosen = entry_codecs(manifest, IRBuilder(lib.get))
    out = tmp_path / "pkgs" / "uwgen_fp"
    # No manifest label given: the package must still import (it names the file).
    write_package(render_package(plan_package(lib, [], manifest, "uwgen_fp")), out)
    sys.path.insert(0, str(out.parent))
    try:
        pkg = importlib.import_module("uwgen_fp")
        for (entry, ident), (roots, _codecs) in chosen.items():
            if entry == "topic":
                used = [pkg.TOPICS[ident].codec]
            elif entry == "action":
                action = pkg.ACTIONS[ident]
                used = [action.goal, action.result, action.feedback]
            else:
                used = [pkg.SERVICES[ident].request, pkg.SERVICES[ident].response]
            assert [c.enc.__name__ for c in used] == [func_name("enc", ct.name, ct.suffix) for ct in roots]
            assert [c.dec.__name__ for c in used] == [func_name("dec", ct.name, ct.suffix) for ct in roots]
    finally:
        sys.path.remove(str(out.parent))
        for name in [m for m in sys.modules if m == "uwgen_fp" or m.startswith("uwgen_fp.")]:
            del sys.modules[name]


SECURED = (BASE_MANIFEST.replace("schema_id: 240\n", "schema_id: 240\nsecurity: {key_file: k.key}\n")
           .replace("a: {port: 4000}", "a: {port: 4000, sender_id: 1}")
           .replace("b: {port: 4001}", "b: {port: 4001, sender_id: 2}")
           .replace("publisher: b}", "publisher: b, security: encrypt}"))


@pytest.mark.parametrize("tag", [4, 6])
def test_a_short_tag_changes_the_protected_ids_only(tmp_path, tag):
    secured = SECURED.replace("{key_file: k.key}", f"{{key_file: k.key, tag_bytes: {tag}}}")
    base = fingerprints(tmp_path, manifest=SECURED, name="default")
    short = fingerprints(tmp_path, manifest=secured, name=f"tag{tag}")
    differ = {k for k in base.fingerprints if base.fingerprints[k] != short.fingerprints[k]}
    assert differ == {("topic", 4)}                 # /other is the protected one
    assert base.schema_digest != short.schema_digest


def test_the_default_tag_keeps_the_fingerprints_of_earlier_builds(tmp_path):
    from uwgen.codegen.fingerprint import description
    args = ("topic", [0], 4, "native", "fp_msgs/msg/Other", [], {})
    earlier = description(*args, security="encrypt")            # no tag item: 11 items
    assert description(*args, security="encrypt", tag_bytes=8) == earlier and len(earlier) == 11
    assert description(*args, security="encrypt", tag_bytes=4) == [*earlier, 4]
    assert description(*args, security="off", tag_bytes=4) == earlier[:10]   # unprotected: as ever
    written = SECURED.replace("{key_file: k.key}", "{key_file: k.key, tag_bytes: 8}")
    base = fingerprints(tmp_path, manifest=SECURED, name="default")
    eight = fingerprints(tmp_path, manifest=written, name="eight")
    assert base.fingerprints == eight.fingerprints and base.schema_digest == eight.schema_digest


def test_the_seal_authenticates_the_fingerprints_without_the_tag_item(tmp_path):
    # CCM binds the tag length into the tag; the seal's authenticated data takes each protected
    # id's fingerprint without it, so a side built with another length can recognise a genuine
    # packet (security/taglength.py), while the announced fingerprints differ.
    base = fingerprints(tmp_path, manifest=SECURED, name="default")
    short = fingerprints(tmp_path, manifest=SECURED.replace("{key_file: k.key}",
                                                            "{key_file: k.key, tag_bytes: 4}"), name="short")
    assert base.seal_fingerprints == {}
    assert short.seal_fingerprints == {4: base.fingerprints[("topic", 4)]}
    assert short.fingerprints[("topic", 4)] != base.fingerprints[("topic", 4)]
