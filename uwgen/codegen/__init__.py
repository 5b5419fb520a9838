"""Codec IR and the jinja2 generator that writes generated/.

`generate()` is the programmatic `uwgen build`: tests and tools use it to build codecs
for any set of interfaces into a folder of their choice and import the result.
"""
from __future__ import annotations

import importlib
import sys
from pathlib import Path
from types import ModuleType
from typing import Iterable

from uwgen.manifest.model import NATIVE


def generate(out_dir: Path, package: str, names: Iterable[str] = (), folders: Iterable[Path] = (),
             manifest: Path | None = None, profiles: tuple[str, ...] = (NATIVE,),
             installed: bool = True, all_installed: bool = False) -> ModuleType:
    """Build `package` into `out_dir/package` and import it.

    `names` are interfaces to build (pkg/msg/Name, pkg/srv/Name, pkg/Name) in every
    profile of `profiles`; `folders` add interface folders (their own interfaces are
    built too); `manifest` adds its topics and services; `all_installed` builds every
    installed interface. Types a profile can never carry are left out of bulk builds
    (see the plan's `skipped`). Raises DefinitionError, ManifestError or ProfileError.
    """
    from uwgen.codegen.generator import plan_build
    from uwgen.codegen.render import render_package, write_package

    plan = plan_build([Path(f) for f in folders], list(names), manifest, package, tuple(profiles),
                      installed, all_installed)
    write_package(render_package(plan), Path(out_dir) / package)
    return import_package(Path(out_dir), package)


def import_package(parent: Path, package: str) -> ModuleType:
    """Import (or re-import) a generated package that lives in `parent/package`."""
    parent = str(Path(parent).resolve())
    if parent not in sys.path:
        sys.path.insert(0, parent)
    for name in [m for m in sys.modules if m == package or m.startswith(package + ".")]:
        del sys.modules[name]
    importlib.invalidate_caches()
    return importlib.import_module(package)
