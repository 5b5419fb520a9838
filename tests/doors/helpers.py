"""Knocking on uwgen's doors: run a command in this process and sort what came out.

Every door (a manifest, a .msg/.srv/.action text, a command line, a key or state file) must
answer bad input with a clear error (a located `file:line:column` where there is a file) or
with success; never with a traceback. `cli()` runs `uwgen ARGS` in this process, so any
exception other than argparse's exit fails the calling test with its traceback.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from uwgen.cli import main as uwgen_main

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "msg_samples"


def cli(capsys, *argv: str) -> tuple[int, str]:
    """(exit status, stdout + stderr) of `uwgen ARGV` run here; argparse's exit is status 2."""
    try:
        rc = uwgen_main([str(a) for a in argv])
    except SystemExit as exc:   # argparse: usage error (2) or --help (0)
        rc = exc.code if isinstance(exc.code, int) else 2
    out = capsys.readouterr()
    return rc, out.out + out.err


def bounded(code: str, seconds: float = 20.0, argv: list[str] = ()) -> subprocess.CompletedProcess:
    """Run Python `code` in a child process that must finish within `seconds` (a hang, such
    as a regular expression backtracking for minutes, fails the test instead of blocking the
    suite: a hung C regex cannot be interrupted in this process)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    try:
        return subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True,
                              timeout=seconds, env=env, cwd=ROOT)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"still running after {seconds} s: {code}") from None


def examples(n: int) -> int:
    """`n` hypothesis examples, times UWGEN_DOORS_SCALE (default 1): the suite runs a modest
    count; `UWGEN_DOORS_SCALE=70 pytest tests/doors` runs the large counts the goals name."""
    return max(1, int(n * float(os.environ.get("UWGEN_DOORS_SCALE", "1"))))


PIPELINE_MANIFEST = """\
network: fuzz
sides:
  a: {{port: 5000}}
  b: {{port: 5001}}
{section}:
  - {{name: /fuzz, id: 3, type: fuzzpkg/{kind}/Fuzz, {who}}}
"""
KIND_OF = {"msg": ("topics", "publisher: a, profile: {profile}"),
           "srv": ("services", "server: a, profile: {profile}"),
           "action": ("actions", "server: a")}


def definition_through_build(folder: Path, text: str, kind: str, profile: str = "native") -> str:
    """Run the definition `text` (a .msg, .srv or .action) through everything a build and an
    analysis do with it, in this process: parse, plan and render the package, analyse the
    sizes. Returns "built", or the located error's text; any other exception escapes."""
    from uwgen.analyze import analyze
    from uwgen.codegen.generator import plan_build
    from uwgen.codegen.render import render_package
    from uwgen.errors import ErrorList
    from uwgen.idl.loader import InterfaceLibrary
    from uwgen.idl.model import DefinitionError
    from uwgen.manifest.loader import ManifestError, load_manifest

    pkg = folder / "fuzzpkg" / kind
    pkg.mkdir(parents=True, exist_ok=True)
    (pkg / f"Fuzz.{kind}").write_text(text, encoding="utf-8")
    section, who = KIND_OF[kind]
    manifest = folder / "uwgen.yaml"
    manifest.write_text(PIPELINE_MANIFEST.format(section=section, kind=kind, who=who.format(profile=profile)))
    try:
        plan = plan_build([folder], manifest_path=manifest, profiles=(profile,))
        render_package(plan)
        lib = InterfaceLibrary([folder], installed=True)
        analyze(load_manifest(manifest, lib), lib.get)
    except (DefinitionError, ManifestError, ErrorList) as exc:
        return str(exc)
    return "built"
