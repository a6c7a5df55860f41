"""What a new user reads is what replay does (issue 40 item 6): the commands of
docs/first_ten_minutes.md run as written, in a fresh directory, and print what the page shows;
docs/evo.md's "not offered" flags are not offered; a refused eval leaves no directory behind.

The page's outputs are compared line by line after removing what depends on the machine: the
``us/step`` column (µs per step), times (``12 s``, ``(49 s)``), the one-time notes of kernels being
compiled and the ``...`` of an elided output. Every other line the page shows must appear, in its
order, in what the command printed.
"""
import re
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGE = DOCS / "first_ten_minutes.md"


def _blocks(text: str) -> list[tuple[str, list[str]]]:
    """The fenced blocks of a page in order: (language, lines)."""
    return [(m.group(1), m.group(2).splitlines()) for m in re.finditer(r"```(\w*)\n(.*?)```", text, re.S)]


def _sections(text: str) -> dict[str, str]:
    parts = re.split(r"^## ", text, flags=re.M)
    return {p.split("\n", 1)[0]: p for p in parts[1:]}


def _steps(section: str) -> list[tuple[str, list[str]]]:
    """(command, lines the page says it prints) of each ``replay`` command of a section's sh blocks:
    the ``# ...`` lines after it, a trailing ``# ...`` comment, and the output block that follows
    its block (the next plain block before the next sh block; a listing of runs/ is not output)."""
    steps, blocks = [], _blocks(section)
    for i, (lang, lines) in enumerate(blocks):
        if lang != "sh":
            continue
        for line in lines:
            if line.startswith("replay "):
                cmd, _, comment = line.partition("  #")
                steps.append((cmd.strip(), [comment.strip()] if comment.strip() else []))
            elif line.startswith("# ") and steps:
                steps[-1][1].append(line[2:])
        out = next((b for b in blocks[i + 1 :] if b[0] == "" and not b[1][0].startswith("runs/")), None)
        nxt = next((j for j in range(i + 1, len(blocks)) if blocks[j][0] == "sh"), len(blocks))
        if out is not None and blocks.index(out, i + 1) < nxt:
            steps[-1][1].extend(out[1])
    return steps


def _normal(lines: list[str]) -> list[str]:
    """Lines without what depends on the machine (module docstring)."""
    out, col = [], None
    for line in lines:
        line = re.sub(r"replay: note: compiling [^\n]*?(cached for later runs\)(\.\.\.)?|$)", "", line).rstrip()
        if "us/step" in line:
            col = line.index("us/step") + len("us/step")  # right-aligned: a cell ends there
        elif col is not None and len(line) >= col and line[col - 1].isdigit():
            start = line.rfind(" ", 0, col) + 1
            line = line[:start] + "#" + line[col:]
        line = re.sub(r" {2,}", "  ", re.sub(r"\d+(\.\d+)? s\b", "T s", line))  # widths follow the cells
        line = re.sub(r"^(\[\d+/\d+\]) \S+ done at", r"\1 done at", line)  # jobs of a pool: any order
        line = re.sub(r"^(\w+: \d+/\d+ jobs) \(.*, \S+ done$", r"\1 done", line)  # share, ETA and name vary
        if line.strip() and line.strip() != "...":
            out.append(line)
    return out


def _run(cmd: str, cwd: Path, shared: Path | None = None) -> list[str]:
    args = cmd.split()[1:]
    if shared is not None:
        args = [str(shared / "datasets") if a == "../shared/datasets" else a for a in args]
    res = subprocess.run([sys.executable, "-m", "replay.cli", *args], cwd=cwd, capture_output=True, text=True,
                         timeout=900)
    assert res.returncode == 0, f"{cmd}\n{res.stdout}\n{res.stderr}"
    return (res.stderr + res.stdout).splitlines()


def _check(cmd: str, said: list[str], printed: list[str]) -> None:
    want, got = _normal(said), _normal(printed)
    it = iter(got)
    missing = [w for w in want if not any(g == w for g in it)]  # each in order (a subsequence)
    assert not missing, f"{cmd}: the page shows lines it does not print:\n" + "\n".join(missing) + \
        "\n--- printed:\n" + "\n".join(got)


def _run_sections(names: list[str], cwd: Path, shared: Path | None = None) -> int:
    sections = _sections(PAGE.read_text())
    n = 0
    for name in names:
        section = next(v for k, v in sections.items() if k.startswith(name))
        for cmd, said in _steps(section):
            _check(cmd, said, _run(cmd, cwd, shared))
            n += 1
    return n


@pytest.mark.slow
def test_the_first_ten_minutes_eval_report_and_export_print_what_the_page_shows(tmp_path):
    """Sections 1-5 (no data needed): --version, the evaluation's table, the report, the export
    (its message count and how to open the file in Foxglove).
    Slow: the README's 20-run evaluation, its report and export (30-40 s); the fast subset keeps
    test_steps_are_read_from_the_page (the page's commands), tests/test_cli.py (eval), tests/test_report.py and
    tests/test_export_foxglove.py."""
    n = _run_sections(["1.", "2.", "4.", "5."], tmp_path)
    assert n == 4  # --version, eval, report, export
    assert (tmp_path / "runs/sim_auv-sonar/sonar/001/leaderboard.csv").is_file()
    assert (tmp_path / "auv-sonar.mcap").is_file() and (tmp_path / "auv-sonar_bag").is_dir()


@pytest.mark.slow
def test_the_first_ten_minutes_campaign_and_reproduction_print_what_the_page_shows(tmp_path, shared_dir):
    """Sections 6-7: the campaign (Bohai from ../shared, as the campaign file finds it) and
    ``replay reproduce 002 --quick`` (about 30-50 s)."""
    camp = Path(__file__).resolve().parents[1] / "campaigns" / "example.toml"
    (tmp_path / "campaigns").mkdir()
    text = camp.read_text().replace('data_dir = "../../shared/datasets"', f'data_dir = "{shared_dir / "datasets"}"')
    assert text != camp.read_text()
    (tmp_path / "campaigns" / "example.toml").write_text(text)
    assert _run_sections(["6.", "7."], tmp_path, shared_dir) == 4  # campaign, report, export, reproduce
    said = re.search(r"(\d+) claims reproduced and (\d+) not reproduced of (\d+)", PAGE.read_text()).groups()
    got = re.search(r"(\d+) reproduced, .* (\d+) not reproduced \(of (\d+) claims\)",
                    (tmp_path / "quick" / "002.md").read_text()).groups()
    assert said == got  # the page's count of the quick run's verdicts


def test_steps_are_read_from_the_page():
    steps = _steps(_sections(PAGE.read_text())["5. Export to Foxglove (1 second)"])
    assert [c for c, _ in steps] == ["replay export runs/sim_auv-sonar/sonar/001 --mcap auv-sonar.mcap "
                                     "--ros2-bag auv-sonar_bag"]
    assert any("Foxglove" in line for line in steps[0][1])
    assert _normal(["ekf   2.4  3.5      10.5  0/20", "filter  pos  med  us/step  diverged",
                    "ekf      2.4  3.5   277.8  0/20", "wrote x (49 s)"]) == [
        "ekf  2.4  3.5  10.5  0/20", "filter  pos  med  us/step  diverged", "ekf  2.4  3.5  #  0/20", "wrote x (T s)"]


def test_evo_page_lists_as_not_offered_no_flag_that_replay_score_offers():
    from click.testing import CliRunner

    from replay.cli import main

    text = (DOCS / "evo.md").read_text()
    sentence = text[text.index("Not offered:"):].split(".\n")[0]
    flags = re.findall(r"`(--[a-z_]+)", sentence)
    assert flags == ["--change_unit", "--ros_map_yaml", "--rerun"], flags
    helptext = CliRunner().invoke(main, ["score", "--help"]).output
    for flag in flags:
        assert flag not in helptext and flag.replace("_", "-") not in helptext, flag
    for offered in ("--sync_method", "--t_start", "--t_end", "--downsample", "--motion_filter", "--project_to_plane"):
        assert offered in helptext  # the five the page called "not offered" before


def test_a_refused_eval_leaves_no_directory_behind(tmp_path):
    from replay.outputs.rundirs import claimed_run_dir

    root = tmp_path / "runs"
    with pytest.raises(RuntimeError):
        with claimed_run_dir("sim/x", "t", root=root):
            raise RuntimeError("refused after the claim")
    assert not root.exists()  # runs/, runs/sim_x and runs/sim_x/t were made by it: gone
    (root / "keep").mkdir(parents=True)
    with claimed_run_dir("sim/x", "t", root=root) as held:  # another run's claim in the directory
        with pytest.raises(RuntimeError):
            with claimed_run_dir("sim/x", "t", root=root) as d:
                assert d.name == "002"
                raise RuntimeError
        assert held.is_dir() and (root / "sim_x" / "t").is_dir()  # in use: kept
    assert sorted(p.name for p in root.iterdir()) == ["keep"]  # the first claim is gone too, and what it made
