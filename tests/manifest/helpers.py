"""Shared set-up for manifest tests: the sample interface library and a YAML writer."""
from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from uwgen.idl.loader import InterfaceLibrary
from uwgen.manifest.loader import ManifestError, load_manifest

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "msg_samples"
DATA = Path(__file__).parent / "data"

_LIB: InterfaceLibrary | None = None


def library() -> InterfaceLibrary:
    global _LIB
    if _LIB is None:
        _LIB = InterfaceLibrary(folders=[SAMPLES], installed=True)
    return _LIB


def write_manifest(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "uwgen.yaml"
    path.write_text(textwrap.dedent(text).lstrip("\n"))
    return path


def load_text(tmp_path: Path, text: str):
    return load_manifest(write_manifest(tmp_path, text), library())


def error_of(tmp_path: Path, text: str) -> ManifestError:
    path = write_manifest(tmp_path, text)
    with pytest.raises(ManifestError) as info:
        load_manifest(path, library())
    error = info.value
    assert str(error) == f"{error.where}: {error.message}"
    assert error.where.path == path
    return error


# A valid two-sided network that tests extend (indented like the tests' own text, which
# is dedented as a whole).
SIDES = """
        network: demo
        sides:
          surface: {port: 4000}
          vehicle: {port: 4001}
"""
