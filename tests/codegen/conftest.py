"""Codecs for every installed interface, built once per test session."""
from __future__ import annotations

import pytest

from uwgen.codegen import generate
from uwgen.idl.loader import InterfaceLibrary


@pytest.fixture(scope="session")
def library() -> InterfaceLibrary:
    return InterfaceLibrary([], installed=True)


@pytest.fixture(scope="session")
def allcodecs(tmp_path_factory):
    """Every installed interface, in both profiles."""
    return generate(tmp_path_factory.mktemp("gen"), "uwgen_all_installed", all_installed=True,
                    profiles=("native", "rmw_desert"))
