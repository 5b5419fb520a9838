"""A package `uwgen build` writes again is what the next import runs."""
from __future__ import annotations

import importlib
import importlib.util
import os
import sys

from uwgen.codegen.render import write_package


def test_a_module_rebuilt_at_the_same_size_and_second_is_imported_anew(tmp_path, monkeypatch):
    # Python takes cached bytecode for a source of the same size and mtime in whole
    # seconds: a rebuild within a second of the last import that changed one digit
    monkeypatch.setattr(sys, "dont_write_bytecode", False)       # cached, as by default
    monkeypatch.syspath_prepend(str(tmp_path))
    package = tmp_path / "uwgen_rebuilt"
    write_package({"__init__.py": "PORT = 4001\n"}, package)
    stat = (package / "__init__.py").stat()
    assert importlib.import_module("uwgen_rebuilt").PORT == 4001
    assert os.path.exists(importlib.util.cache_from_source(str(package / "__init__.py")))

    assert write_package({"__init__.py": "PORT = 4002\n"}, package) == ["__init__.py"]
    os.utime(package / "__init__.py", ns=(stat.st_atime_ns, stat.st_mtime_ns))
    del sys.modules["uwgen_rebuilt"]
    assert importlib.import_module("uwgen_rebuilt").PORT == 4002
