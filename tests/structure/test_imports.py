"""The package's structure: no import circles, and no import up the layers.

Every `import` statement of every module counts, also those inside functions (a lazy
import is still a dependency: it only moves the failure to run time); only imports for
annotations (`if TYPE_CHECKING:`) do not.
"""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "uwgen"
# Lower layers never import from higher ones; the manifest model is below the runtime
# (the runtime's link and codec table read it), never the other way round.
HIGHER = ("uwgen.bridge", "uwgen.commands", "uwgen.demo")
LOWER = ("uwgen.idl", "uwgen.manifest", "uwgen.runtime")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path) -> set[str]:
    """The uwgen modules `path` imports (a `from pkg import name` of a submodule counts as it)."""
    here = module_name(path)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    found: set[str] = set()
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for guard in ast.walk(tree):   # `if TYPE_CHECKING:` imports are for annotations only
        if isinstance(guard, ast.If) and getattr(guard.test, "id", None) == "TYPE_CHECKING":
            guard.body = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")
                parent = parent[:len(parent) - node.level + 1]
                base = ".".join(parent + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{a.name}" for a in node.names)
    return {m for m in found if m == "uwgen" or m.startswith("uwgen.")}


def graph() -> dict[str, set[str]]:
    modules = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    return {name: {m for m in imports_of(path) if m in modules and m != name}
            for name, path in modules.items()}


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def _without_package_inits(g: dict[str, set[str]]) -> dict[str, set[str]]:
    # A package's __init__ re-exporting its submodules is not a circle of design.
    return {v: {w for w in ws if not v.startswith(w + ".")} for v, ws in g.items()}


def test_the_cycle_finder_finds_a_circle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_imports_another_that_imports_it_back():
    assert cycles(_without_package_inits(graph())) == []


def test_the_demo_command_and_drive_away_do_not_import_each_other():
    g = graph()
    assert "uwgen.commands.demo" not in g["uwgen.demo.drive_away"]


def test_lower_layers_import_nothing_from_higher_ones():
    up = sorted((v, w) for v, ws in graph().items() if v.startswith(LOWER)
                for w in ws if w.startswith(HIGHER))
    assert up == []


def test_the_manifest_model_needs_nothing_from_the_runtime():
    g = graph()
    assert sorted(w for v, ws in g.items() if v.startswith("uwgen.manifest")
                  for w in ws if w.startswith("uwgen.runtime")) == []


def test_a_carried_module_imports_only_carried_modules():
    from uwgen.codegen.vendor import CARRIED
    carried = set(CARRIED.values())
    g = graph()
    assert sorted((v, w) for v in carried for w in g[v] if w not in carried) == []


# The runtime's rooms, lowest first (uwgen/runtime/__init__.py): a module may import its own
# room and the rooms below it, never one above. clock and stats are the floor every room uses.
RUNTIME_ROOMS = ("uwgen.runtime.clock", "uwgen.runtime.stats", "uwgen.runtime.wire",
                 "uwgen.runtime.link", "uwgen.runtime.delivery")


def _room(module: str) -> int | None:
    for rank, room in enumerate(RUNTIME_ROOMS):
        if module == room or module.startswith(room + "."):
            return max(rank, 1)   # clock and stats are one floor
    return None


def test_the_runtime_has_no_flat_room_of_modules():
    top = sorted(p.stem for p in (PACKAGE / "runtime").glob("*.py") if p.stem != "__init__")
    assert top == ["clock", "stats"]


def test_runtime_rooms_import_only_their_own_room_or_lower_ones():
    up = sorted((v, w) for v, ws in graph().items() if _room(v) is not None
                for w in ws if _room(w) is not None and _room(w) > _room(v))
    assert up == []


def test_the_room_check_sees_an_upward_import():
    assert _room("uwgen.runtime.delivery.acks") > _room("uwgen.runtime.wire.codec")
    assert _room("uwgen.runtime.clock") == _room("uwgen.runtime.stats")


def test_the_field_kit_reads_recordings_without_the_bridge():
    # The bridge records through the field kit's writer; the kit's readers and tables take the
    # books from the runtime's ledger, so neither package needs the other back.
    g = graph()
    assert sorted((v, w) for v, ws in g.items() if v.startswith("uwgen.fieldkit")
                  for w in ws if w.startswith("uwgen.bridge")) == []
