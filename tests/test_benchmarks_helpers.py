"""The pure helpers of the benchmark scripts (no timing is tested)."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import bench_coldstart  # noqa: E402
import gauge  # noqa: E402


def test_readme_command_takes_the_replay_part_after_the_last_and():
    text = "intro\n```sh\npython3 -m venv .venv && .venv/bin/pip install -q -e \".[test]\" && " \
           ".venv/bin/replay eval sim/auv-sonar --runs 20\n```\n.venv/bin/replay other\n"
    assert bench_coldstart.readme_command(text) == ["replay", "eval", "sim/auv-sonar", "--runs", "20"]


def test_readme_command_of_the_repository_readme_is_found():
    # bench_coldstart reads the README's first command: this fails if the README's format changes
    text = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    assert bench_coldstart.readme_command(text)[:3] == ["replay", "eval", "sim/auv-sonar"]


def test_readme_command_missing_is_one_clear_error():
    with pytest.raises(ValueError, match="README.md"):
        bench_coldstart.readme_command("no command here")


def test_layout_puts_mapped_directories_under_their_package_parents_first():
    pairs = bench_coldstart.layout({"replay.filters": "filters", "replay": "replay", "replay.adapters": "adapters"})
    assert pairs == [("replay", "replay"), ("adapters", "replay/adapters"), ("filters", "replay/filters")]


def test_fresh_copy_builds_the_installed_layout_without_caches(tmp_path):
    root = tmp_path / "src"
    for d in ("replay", "filters/__pycache__", "datasets"):
        (root / d).mkdir(parents=True)
    (root / "replay" / "__init__.py").write_text("")
    (root / "filters" / "pf.py").write_text("x = 1\n")
    (root / "filters" / "__pycache__" / "pf.cpython-311.pyc").write_bytes(b"\0")
    (root / "datasets" / "sim.toml").write_text("")
    (root / "pyproject.toml").write_text('[tool.setuptools.package-dir]\n"replay" = "replay"\n'
                                         '"replay.filters" = "filters"\n"replay.adapters" = "adapters"\n')
    dest = bench_coldstart.fresh_copy(root, tmp_path / "copy")
    files = sorted(str(p.relative_to(dest)) for p in dest.rglob("*") if p.is_file())
    assert files == ["datasets/sim.toml", "pyproject.toml", "replay/__init__.py", "replay/filters/pf.py"]


def test_others_share_subtracts_our_own_cpu():
    # 1000 ticks elapsed, 600 busy, we used 4 s at 100 Hz = 400 ticks: others 200 / 1000
    assert gauge.others_share(600, 1000, 4.0, 100) == pytest.approx(0.2)
    assert gauge.others_share(300, 1000, 4.0, 100) == 0.0
    assert gauge.others_share(10, 0, 0.0, 100) is None


def test_verdict_direction_and_missing_values():
    assert gauge.verdict(1.0, 2.0) == "PASS"
    assert gauge.verdict(3.0, 2.0) == "MISS"
    assert gauge.verdict(1.8, 1.7, higher_is_better=True) == "PASS"
    assert gauge.verdict(1.2, 1.7, higher_is_better=True) == "MISS"
    assert gauge.verdict(float("nan"), 1.0) == "n/a"
    assert gauge.verdict(None, 1.0) == "n/a"
