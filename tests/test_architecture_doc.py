"""docs/architecture.md's "Where things live" against the tree: every path it names exists, every folder
of the tree (and every module at the top of replay/) is named, and its checklists name real files."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "architecture.md").read_text()
SKIP = {"runs", "__pycache__", "build", "dist", "img", "mappings", "reproduction"}


def _section(title: str) -> str:
    start = DOC.index(f"## {title}\n")
    end = DOC.find("\n## ", start + 1)
    return DOC[start:end if end > 0 else None]


def _rows() -> dict:
    """{path in the first column: the row's text}."""
    rows = {}
    for line in _section("Where things live").splitlines():
        m = re.match(r"\| `([^`]+)` \|(.*)\|$", line)
        if m:
            rows[m.group(1)] = m.group(2)
    return rows


def _folders() -> set:
    """The tree's folders: the top level, and one level down in the three packages' roots (and examples/)."""
    out = set()
    for d in sorted(ROOT.iterdir()):
        if d.is_dir() and not d.name.startswith(".") and d.name not in SKIP and not d.name.endswith(".egg-info"):
            out.add(f"{d.name}/")
    for top in ("replay", "adapters", "filters"):
        out |= {f"{top}/{d.name}/" for d in (ROOT / top).iterdir() if d.is_dir() and d.name not in SKIP}
    return out


def test_every_path_named_exists_and_every_folder_is_named():
    rows = _rows()
    assert len(rows) > 20
    missing = [p for p in rows if not (ROOT / p).exists()]
    assert not missing, f"named in 'Where things live' but not in the tree: {missing}"
    unnamed = sorted(_folders() - set(rows))
    assert not unnamed, f"folders of the tree missing from 'Where things live': {unnamed}"


def test_the_top_of_replay_holds_the_modules_the_doc_names():
    named = set(re.findall(r"`(\w+\.py)`", _rows()["replay/"]))
    assert named == {p.name for p in (ROOT / "replay").glob("*.py")}


def test_files_named_in_the_rows_and_checklists_exist():
    """Every `dir/file.py`-like path in the rows' text and the checklists names a file of the tree."""
    text = "\n".join(_rows().values()) + _section("Checklists")
    paths = set(re.findall(r"`((?:adapters|filters|replay|tests|benchmarks|datasets)/[\w/.-]*\.(?:py|md|toml))(?::\w+)?`", text))
    assert len(paths) > 10
    assert [p for p in sorted(paths) if not (ROOT / p).exists()] == []
    assert {"Add a built-in filter", "Add a sensor role", "Add a task", "Add an adapter"} <= set(
        re.findall(r"^### (.+)$", _section("Checklists"), re.M))
