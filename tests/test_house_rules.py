"""The house's size rules, checked on the library's source (docs/architecture.md, "Rules"): no file over 400 lines, no
function over 100 lines, none in replay/reproduce/ over 60; each paper reproduction is its table and its prose
under replay/papers/ beside one module."""
import ast
from pathlib import Path

import pytest

from replay.reproduce import REPRODUCTIONS

ROOT = Path(__file__).resolve().parents[1]
SOURCES = sorted(p for d in ("replay", "adapters", "filters") for p in (ROOT / d).rglob("*.py"))


def lengths(path: Path):
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node.name, node.end_lineno - node.lineno + 1


def test_the_rules_see_the_library():
    assert len(SOURCES) > 200 and ROOT / "replay/reproduce/rules.py" in SOURCES


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_files_and_functions_stay_small(path):
    assert len(path.read_text(encoding="utf-8").splitlines()) <= 400
    limit = 60 if "reproduce" in path.parts else 100
    assert [(name, n) for name, n in lengths(path) if n > limit] == []


@pytest.mark.parametrize("paper", sorted(REPRODUCTIONS))
def test_a_reproduction_is_its_table_its_prose_and_one_module(paper):
    papers = ROOT / "replay/papers"
    assert (papers / f"{paper}.toml").is_file() and (papers / f"{paper}.md").is_file()
    assert REPRODUCTIONS[paper] == f"replay.reproduce.p{paper}:run"
    assert sorted(p.name for p in (ROOT / "replay/reproduce").glob(f"p{paper}*.py")) == [f"p{paper}.py"]
