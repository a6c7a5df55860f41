"""Tables of the paper-002 reproduction: one row per filter configuration, from ``replay eval``'s pipeline.

Every number here is read from an :class:`replay.run.evaluation.Evaluation` (the
leaderboard rows of :mod:`replay.scoring.summary` and the per-run records and errors of
:func:`replay.run.pipeline.run_block`): mean ± 95 % half-width, median, ``lost k/N``,
``diverged k/N``, the paired difference against a reference row
(:func:`replay.scoring.summary.add_paired`, common random numbers), and the mean 3-D
Euclidean error beside the 3-D RMSE (:func:`position_definitions`, from the
scorer's per-step errors). :class:`Entry` is one row; :func:`table` renders rows.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from replay.scoring import summary
from replay.run.manifest import command_line
from replay.reproduce.verdict import cell as text_cell
from replay.reproduce.verdict import mean_ci
from replay.scoring.scorer import ci95
from replay.scoring.summary import lost_cell


# --- numbers of one result -------------------------------------------------------------
def cell(values):
    """(mean, 95 % half-width) of the finite values."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return (float(v.mean()) if len(v) else float("nan")), ci95(v)


def fmt(x, digits=3):
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "n/a"
    return "n/a" if not np.isfinite(x) else f"{x:.{digits}f}"


def pm(pair, digits=3) -> str:
    """``mean ± half-width`` of a (mean, ci) pair."""
    mean, ci = pair
    if not np.isfinite(mean):
        return "n/a"
    return f"{mean:.{digits}f}" + (f" ± {ci:.{digits}f}" if np.isfinite(ci) else "")


def position_definitions(errors: list[np.ndarray]) -> dict[str, np.ndarray]:
    """Per-run values of each candidate "position error" from per-run (n, d) error arrays."""
    out = {"rmse3": [], "rmse2": [], "mean3": [], "mean2": []}
    for e in errors:
        e = e[np.isfinite(e).all(axis=1)]
        d3, d2 = np.sum(e**2, axis=1), np.sum(e[:, :2] ** 2, axis=1)
        out["rmse3"].append(np.sqrt(d3.mean()))
        out["rmse2"].append(np.sqrt(d2.mean()))
        out["mean3"].append(np.sqrt(d3).mean())
        out["mean2"].append(np.sqrt(d2).mean())
    return {k: np.array(v) for k, v in out.items()}


DEFINITIONS = {
    "rmse3": "3-D RMSE sqrt(mean_k |e_k|²) = sqrt(X² + Y² + Z²) (the scorer's pos_rmse)",
    "rmse2": "horizontal RMSE sqrt(mean_k (e_x² + e_y²)) = sqrt(X² + Y²) per run",
    "mean3": "mean over steps of the 3-D Euclidean error |e_k|",
    "mean2": "mean over steps of the horizontal Euclidean error",
}


def ok_runs(result) -> list[int]:
    return [i for i, m in enumerate(result.runs) if not m["diverged"]]


def definitions(result) -> dict[str, np.ndarray]:
    """:func:`position_definitions` of the runs of ``result`` that did not diverge."""
    return position_definitions([result.errors[i]["position"] for i in ok_runs(result)])


# --- rows ------------------------------------------------------------------------------
@dataclass
class Entry:
    """One row of a table: a filter configuration of an evaluation, under a display name."""

    name: str
    row: dict  # the leaderboard row (replay.scoring.summary)
    result: object  # replay.run.evaluation.FilterResult
    ev: object  # replay.run.evaluation.Evaluation
    paper: float | None = None
    paired: tuple | None = None
    extra: dict = field(default_factory=dict)

    @property
    def command(self) -> str:
        return command_line(self.ev.config)

    def value(self, key="pos_rmse"):
        return float(self.row.get(key, np.nan))

    def pair(self, key="pos_rmse"):
        return self.value(key), float(self.row.get(f"{key}_ci95", np.nan))

    def mean3(self):
        return cell(definitions(self.result)["mean3"])


def entries(ev, names: dict | None = None, paper: dict | None = None, only=None) -> list[Entry]:
    """The rows of ``ev`` (optionally ``only`` some filters), named by ``names`` (filter -> name)."""
    names, paper = names or {}, paper or {}
    out = []
    for row, res in zip(ev.rows, ev.results):
        if only is None or res.name in only:
            out.append(Entry(names.get(res.name, res.name), dict(row), res, ev, paper.get(res.name)))
    return out


def find(rows: list[Entry], name: str) -> Entry:
    return next(e for e in rows if e.name == name)


def add_paired(rows: list[Entry], reference: str) -> None:
    """Each row's paired difference of ``pos_rmse`` minus that of the row named ``reference`` in the
    same runs (:func:`replay.scoring.summary.add_paired`; rows on other measurements get none)."""
    copies = [dict(e.row, label=f"#{i}") for i, e in enumerate(rows)]
    ref = next(i for i, e in enumerate(rows) if e.name == reference)
    configs, records = {}, {}
    for c, e in zip(copies, rows):
        c["config_hash"] = f"{c['config_hash']}#{id(e)}"  # the same configuration may appear in two tables
        configs[c["config_hash"]], records[c["config_hash"]] = e.result.config, e.result.records
    summary.add_paired(copies, configs, records, baseline=f"#{ref}")
    col = f"pos_rmse_vs_#{ref}"
    for c, e in zip(copies, rows):
        v = c.get(col, "")
        e.paired = None if v in ("", None) else (float(v), float(c[f"{col}_ci95"]))


COLUMNS = {
    "paper": "paper",
    "pos": "position RMSE (m) ± 95 %",
    "ratio": "ours ÷ paper",
    "mean3": "mean 3-D error (m) ± 95 %",
    "median": "median RMSE",
    "lost": "lost",
    "diverged": "diverged",
    "x": "X RMSE",
    "y": "Y RMSE",
    "pitch": "pitch RMSE (rad)",
    "yaw": "yaw RMSE (rad)",
    "paired": "Δ position vs {ref} (paired) ± 95 %",
    "us": "µs/step",
}


def table(rows: list[Entry], cols=("pos", "mean3", "median", "lost", "diverged"), ref: str = "",
          digits: int = 3, first: str = "filter") -> list[str]:
    """A Markdown table of ``rows`` with the columns ``cols`` (keys of :data:`COLUMNS`)."""
    head = [first] + [COLUMNS.get(c, c).format(ref=ref) for c in cols]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for e in rows:
        cells = [text_cell(e.name)]
        for c in cols:
            if c == "paper":
                cells.append(fmt(e.paper, 4) if e.paper is not None else "—")
            elif c == "pos":
                cells.append(mean_ci(e.row, "pos_rmse", digits))
            elif c == "ratio":
                cells.append(fmt(e.value() / e.paper, 2) if e.paper else "—")
            elif c == "mean3":
                cells.append(pm(e.mean3(), digits))
            elif c == "median":
                cells.append(fmt(e.value("pos_rmse_median"), digits))
            elif c == "lost":
                cells.append(lost_cell(e.row))
            elif c == "diverged":
                cells.append(f"{e.row.get('diverged', 0)}/{e.row.get('runs', 0)}")
            elif c in ("x", "y", "pitch", "yaw"):
                cells.append(mean_ci(e.row, f"{c}_rmse", digits))
            elif c == "paired":
                cells.append("—" if e.name == ref or e.paired is None else pm(e.paired, digits))
            elif c == "us":
                cells.append(fmt(e.value("us_per_step"), 0))
            else:
                cells.append(text_cell(e.extra.get(c, "")))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def commands(rows: list[Entry], extra: dict | None = None) -> list[str]:
    """The ``replay eval`` commands that give the rows (each once), as Markdown lines."""
    seen = []
    for e in rows:
        if e.command not in seen:
            seen.append(e.command)
    return ["Commands (each gives its rows exactly):", ""] + [f"* `{c}`" for c in seen] + [""]


def ours(e: Entry, key="pos_rmse", digits=3) -> str:
    """Our number with its interval, for the verdict table."""
    return mean_ci(e.row, key, digits) + (f" (lost {lost_cell(e.row)})" if float(e.row.get("lost") or 0) else "")


# --- Monte Carlo convergence (Fig. 9) --------------------------------------------------
def convergence(rows: list[Entry], png) -> list[str]:
    """Fig. 9: running mean of the per-run position RMSE against the Monte Carlo trial index."""
    n = max(e.ev.config["runs"] for e in rows)
    marks = sorted({m for m in (10, 50, 100, 200, 500, n) if m <= n})
    lines = ["| filter | " + " | ".join(f"m = {m}" for m in marks) + " |", "|" + "---|" * (len(marks) + 1)]
    series = {}
    for e in rows:
        v = np.array([np.nan if m["diverged"] else m["pos_rmse"] for m in e.result.runs])
        series[e.name] = v
        lines.append(f"| {e.name} | " + " | ".join(pm(cell(v[:m])) if m <= len(v) else "—" for m in marks) + " |")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return lines + ["", "(plot skipped: matplotlib is not installed)", ""]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for name, v in series.items():
        idx = np.arange(1, len(v) + 1)
        ok = np.isfinite(v)
        run_mean = np.cumsum(np.where(ok, v, 0.0)) / np.maximum(np.cumsum(ok), 1)
        line, = ax.plot(idx, run_mean, lw=2, label=name)
        ax.plot(idx[ok], v[ok], ".", ms=2, alpha=0.3, color=line.get_color())
    ax.set_yscale("log")
    ax.set_xlabel("Monte Carlo trial")
    ax.set_ylabel("position RMSE (m): per trial (dots), running mean (lines)")
    ax.set_title(f"paper 002, sim/auv-sonar, Table 5 setup, up to {n} trials")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=80)
    plt.close(fig)
    return lines + ["", f"![convergence]({png.name})", ""]
