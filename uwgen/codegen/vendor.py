"""The runtime a generated package carries, so that a copy of it works without uwgen.

Every generated package gets a `_runtime/` folder with copies of the modules its code
imports (standard library and cbor2 only), and its modules import from there:

    generated/uwgen_demo/_runtime/__init__.py   chooses: uwgen's own modules, or the copies
    generated/uwgen_demo/_runtime/codec.py      copy of uwgen/runtime/wire/codec.py, imports made relative
    ...

`CARRIED` is the one list of those modules: a new helper that generated code imports
(e.g. `uwgen.runtime.wire.bits`) is one more line there. A carried module may import only the
standard library, cbor2 and other carried modules (as `from uwgen.runtime.x import ...`,
rewritten to `from .x import ...`); anything else fails the build with VendorError.

Where uwgen itself is importable and its modules are byte-for-byte the ones copied,
`_runtime` uses uwgen's modules (one set of codec and exception classes per process, so
a bridge catches what a generated codec raises); anywhere else it uses the copies.
"""
from __future__ import annotations

import hashlib
import importlib.util
import re
from pathlib import Path

# name in _runtime/ -> uwgen module it is a copy of. Keep in dependency order.
CARRIED = {
    "codec": "uwgen.runtime.wire.codec",
    "typed_arrays": "uwgen.runtime.wire.typed_arrays",
    "columns": "uwgen.runtime.wire.columns",
    "model": "uwgen.manifest.model",
    "framing": "uwgen.runtime.wire.framing",
    "bits": "uwgen.runtime.wire.bits",
    "rosclasses": "uwgen.runtime.wire.rosclasses",
    "table": "uwgen.runtime.wire.table",
}
FOLDER = "_runtime"

_IMPORT = re.compile(r"^(?P<indent>\s*)from (?P<module>uwgen(?:\.\w+)+) import ", re.M)
_ANY_UWGEN_IMPORT = re.compile(r"^\s*(?:from|import) uwgen\b", re.M)


class VendorError(Exception):
    """A carried module imports something the generated package does not carry."""


def source_of(module: str) -> tuple[Path, str]:
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        raise VendorError(f"cannot find the source of {module}")
    path = Path(spec.origin)
    return path, path.read_text(encoding="utf-8")


def digest(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def carried_module(name: str, header: str) -> tuple[str, str]:
    """(text of _runtime/<name>.py, digest of the uwgen module it copies)."""
    module = CARRIED[name]
    path, text = source_of(module)
    local = {real: short for short, real in CARRIED.items()}

    def relative(m: re.Match) -> str:
        target = m.group("module")
        if target not in local:
            raise VendorError(f"{path}: imports {target}, which generated packages do not carry "
                              f"(add it to CARRIED in uwgen/codegen/vendor.py if it is stdlib/cbor2-only)")
        return f"{m.group('indent')}from .{local[target]} import "

    lines = []
    guard_indent = None   # inside `if TYPE_CHECKING:` (annotations only: never runs)
    for line in text.splitlines(keepends=True):
        indent = len(line) - len(line.lstrip())
        if guard_indent is not None and line.strip() and indent <= guard_indent:
            guard_indent = None
        if line.lstrip().startswith("if TYPE_CHECKING:"):
            guard_indent = indent
        elif guard_indent is None:
            line = _IMPORT.sub(relative, line)
            if _ANY_UWGEN_IMPORT.search(line):
                raise VendorError(f"{path}: `{line.strip()}` cannot be carried; "
                                  "use `from uwgen.x import name` of a carried module")
        lines.append(line)
    copied = "".join(lines)
    note = f"# Copy of {module} (uwgen/{Path(*module.split('.')[1:])}.py), carried so that this package works without uwgen.\n"
    return header + note + copied, digest(text)


INIT = '''{header}"""The runtime this package carries: {names}.

Where uwgen is importable and its modules are the ones copied here, this package uses
uwgen's own (one set of classes per process); anywhere else (a vendored copy without
uwgen) it uses the copies in this folder. The list is uwgen.codegen.vendor.CARRIED.
"""
import hashlib as _hashlib
import importlib.util as _util
import sys as _sys

# name -> (uwgen module, sha256 prefix of its source when this package was built)
CARRIED = {{
{entries}}}


def _same_as_uwgen():
    for _name, (module, digest) in CARRIED.items():
        try:
            spec = _util.find_spec(module)
        except (ImportError, ValueError):
            return False
        if spec is None or not spec.origin:
            return False
        try:
            with open(spec.origin, "rb") as fh:
                if _hashlib.sha256(fh.read()).hexdigest()[:16] != digest:
                    return False
        except OSError:
            return False
    return True


if _same_as_uwgen():
    import importlib as _importlib
    for _name, (_module, _digest) in CARRIED.items():
        _sys.modules[__name__ + "." + _name] = globals()[_name] = _importlib.import_module(_module)
'''


def runtime_files(header: str) -> dict[str, str]:
    """{relative path: text} of the _runtime/ folder of a generated package."""
    files = {}
    entries = []
    for name, module in CARRIED.items():
        text, dig = carried_module(name, header)
        files[f"{FOLDER}/{name}.py"] = text
        entries.append(f"    {name!r}: ({module!r}, {dig!r}),\n")
    files[f"{FOLDER}/__init__.py"] = INIT.format(header=header, names=", ".join(CARRIED),
                                                 entries="".join(entries))
    return files


def foreign_runtime(package) -> str | None:
    """Why a generated package runs on its carried copies rather than this uwgen's runtime
    (it was generated by another version of uwgen), or None. A bridge needs one runtime:
    it catches the exceptions of uwgen.runtime.wire.codec."""
    import importlib
    runtime = getattr(package, FOLDER, None)
    carried = getattr(runtime, "CARRIED", None)
    if not carried:
        return None
    for name, (module, _digest) in carried.items():
        if getattr(runtime, name, None) is not importlib.import_module(module):
            folder = Path(package.__file__).parent
            return (f"{folder} was generated by another version of uwgen (its {FOLDER}/{name}.py "
                    f"is not this uwgen's {module}): build it again with `uwgen build`")
    return None
