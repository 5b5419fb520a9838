"""The house rules that hold for every file: comments and docs name the design section they
follow, never the history that led to it (history belongs in commit messages), no module
grows past about 450 lines and no class past about 250 (split by responsibility instead)."""
from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# Where code and docs live; tests and benchmarks keep the same rule.
CHECKED = ("uwgen", "docs", "templates", "msg_samples", "generated", "tests", "benchmarks", "README.md")
TEXT_SUFFIXES = {".py", ".md", ".j2", ".yaml", ".yml", ".txt", ".msg", ".srv", ".action", ".toml", ".cfg"}
# the word issue or session (any case, maybe plural), then a number, maybe after '#'
HISTORY = re.compile(r"\b(?:issue|session)s?\s?#?\d+", re.IGNORECASE)

MAX_LINES = 450
# Modules their owners are splitting; an entry goes as soon as its file is within the limit
# (test_the_over_limit_list_names_only_files_still_over_it says when).
OVER_LIMIT = {
    "uwgen/emulator/core.py",
}


MAX_CLASS_LINES = 250
# Classes past the limit, to be split by responsibility; an entry goes as soon as its class
# is within it (test_the_long_class_list_names_only_classes_still_over_it says when).
LONG_CLASSES = {
    "uwgen/manifest/loader.py:_ManifestBuilder",
    "uwgen/runtime/link/connection.py:DesertConnection",
    "uwgen/runtime/link/scheduler.py:LinkScheduler",
    "uwgen/emulator/core.py:EmulatorCore",
    "uwgen/emulator/server.py:Emulator",
    "uwgen/bridge/action_servers.py:ActionServers",
    "uwgen/runtime/delivery/reliability.py:Reliability",
}


def text_files() -> list[Path]:
    out = []
    for name in CHECKED:
        path = ROOT / name
        if path.is_file():
            out.append(path)
            continue
        out += [p for p in sorted(path.rglob("*")) if p.is_file() and p.suffix in TEXT_SUFFIXES
                and "__pycache__" not in p.parts]
    return out


def history_mentions(text: str) -> list[tuple[int, str]]:
    """(line number, the words) of every mention of an issue or session number in `text`."""
    return [(text.count("\n", 0, m.start()) + 1, m.group(0)) for m in HISTORY.finditer(text)]


def test_the_history_finder_finds_issue_and_session_numbers():
    issue, session = "iss" + "ue", "sess" + "ion"      # (spelled apart: this file is checked too)
    text = (f"ok\nsee {issue} 16 and {issue.title()} #9\n### {session.title()} 5: hooks\n"
            f"{issue}s 16 and 17\nSend{session.title()}, 5 s\n")
    assert history_mentions(text) == [(2, f"{issue} 16"), (2, f"{issue.title()} #9"),
                                      (3, f"{session.title()} 5"), (4, f"{issue}s 16")]


def test_code_and_docs_name_sections_not_issues_or_sessions():
    found = []
    for path in text_files():
        text = path.read_text(encoding="utf-8", errors="replace")
        found += [f"{path.relative_to(ROOT)}:{line}: {words!r}" for line, words in history_mentions(text)]
    assert not found, ("name the design section (e.g. 'wire-format.md section 15') instead of "
                       "the history:\n" + "\n".join(found))


def module_lengths() -> dict[str, int]:
    return {str(p.relative_to(ROOT)): len(p.read_text(encoding="utf-8").splitlines())
            for p in sorted((ROOT / "uwgen").rglob("*.py"))}


def test_no_module_is_past_the_line_limit():
    over = {name: n for name, n in module_lengths().items() if n > MAX_LINES and name not in OVER_LIMIT}
    assert not over, f"split by responsibility (limit {MAX_LINES} lines): {over}"


def test_the_over_limit_list_names_only_files_still_over_it():
    lengths = module_lengths()
    done = sorted(name for name in OVER_LIMIT if lengths.get(name, 0) <= MAX_LINES)
    assert not done, f"within {MAX_LINES} lines now (or gone): remove from OVER_LIMIT: {done}"


def class_lengths() -> dict[str, int]:
    out = {}
    for path in sorted((ROOT / "uwgen").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef):
                out[f"{path.relative_to(ROOT)}:{node.name}"] = node.end_lineno - node.lineno + 1
    return out


def test_no_class_is_past_the_line_limit():
    over = {name: n for name, n in class_lengths().items() if n > MAX_CLASS_LINES and name not in LONG_CLASSES}
    assert not over, f"split by responsibility (limit {MAX_CLASS_LINES} lines): {over}"


def test_the_long_class_list_names_only_classes_still_over_it():
    lengths = class_lengths()
    done = sorted(name for name in LONG_CLASSES if lengths.get(name, 0) <= MAX_CLASS_LINES)
    assert not done, f"within {MAX_CLASS_LINES} lines now (or gone): remove from LONG_CLASSES: {done}"
