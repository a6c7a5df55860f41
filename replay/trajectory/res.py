"""``replay res DIR...``: tables of saved results (:mod:`replay.trajectory.archive`) without the inputs, as
evo_res and rpg_trajectory_evaluation's cached results and LaTeX tables.

Two tables (:func:`rows`):

* ``stats`` — one row per archive, estimate, metric and relation: ``results`` (the directory as given),
  ``estimate``, ``trial_of``, ``trial``, ``metric`` (``ape``, ``rpe``, ``rel`` for the relative errors over
  a length), ``relation`` (the pose relation, or the relative error: trans, trans_perc, rot, ...),
  ``length``, ``length_m``, ``unit``, ``n``, then ``rmse, mean, median, std, min, max`` (and ``sse``):
  the numbers ``replay score`` printed, every digit as saved;
* ``trials`` — one row per trial set, length and aggregated metric: ``results``, ``estimate``, ``length``,
  ``metric`` (a leaderboard column such as ``ape_trans_rmse``), ``trials`` (N), ``mean``, ``median``,
  ``ci95`` (half-width of the 95 % t-interval), ``lost`` (k trials, empty when not judged); given
  ``replay eval`` or campaign outputs, the ``recorded:<name>`` rows of one name and task across them
  (one per recording) are aggregated the same way (:func:`across`).

:func:`render` writes them as CSV (every digit, :func:`replay.util.files.fmt`), Markdown or LaTeX (numbers
with ``digits`` significant digits).
"""

from __future__ import annotations

import math

from replay.trajectory.archive import finite
from replay.util.errors import ReplayError
from replay.util.files import csv_text
from replay.trajectory.lengths import UNITS as REL
from replay.trajectory.pose_error import UNITS
from replay.trajectory.trials import aggregate, aggregated_keys

TABLES = ("stats", "trials")
FORMATS = ("csv", "md", "latex")
SUFFIXES = {".csv": "csv", ".md": "md", ".tex": "latex"}
STATS = ("rmse", "mean", "median", "std", "min", "max", "sse")


def _units():

    return UNITS, REL


def stats_rows(archives) -> list[dict]:
    units, rel_units = _units()
    out = []
    for a in archives:
        for e in a.meta["estimates"]:
            base = {
                "results": a.shown,
                "estimate": e["name"],
                "trial_of": e.get("trial_of") or "",
                "trial": e.get("trial") or "",
            }
            for kind, by_rel in e["stats"].items():
                for rel, st in by_rel.items():
                    out.append(
                        {
                            **base,
                            "metric": kind,
                            "relation": rel,
                            "length": "",
                            "length_m": "",
                            "unit": units.get(rel) or "",
                            "n": st["n"],
                            **{k: finite(st.get(k)) for k in STATS},
                        }
                    )
            for label, entry in e.get("lengths", {}).items():
                for err, unit in rel_units.items():
                    st = entry[err]
                    out.append(
                        {
                            **base,
                            "metric": "rel",
                            "relation": err,
                            "length": label,
                            "length_m": entry["length_m"],
                            "unit": unit,
                            "n": st["num_samples"],
                            **{k: finite(st.get(k)) if k in st else "" for k in STATS},
                        }
                    )
    return out


def trials_rows(archives) -> list[dict]:

    out = []
    for a in archives:
        seen = set()
        for row in a.meta["leaderboard"]:
            if row.get("trial", None) != "":
                continue
            name = row["filter"][len("recorded:") :]
            keys = [
                k
                for k in aggregated_keys(row)
                if not k.endswith(("_ci95", "_median")) and (k.startswith("rel_") or name not in seen)
            ]  # a length's row repeats the APE/RPE
            seen.add(name)
            for k in keys:
                out.append(
                    {
                        "results": a.shown,
                        "estimate": name,
                        "length": row.get("length", "") if k.startswith("rel_") else "",
                        "metric": k,
                        "trials": row["runs"],
                        "mean": finite(row[k]),
                        "median": finite(row.get(f"{k}_median")),
                        "ci95": finite(row.get(f"{k}_ci95")),
                        "lost": row.get("lost", ""),
                    }
                )
    return out


def across(boards) -> list[dict]:
    """Trials-table rows of the recorded estimates of ``replay eval`` / campaign outputs: ``boards`` is
    ``[(shown, leaderboard rows)]``; the ``recorded:<name>`` rows of one name and task in different
    directories (one per recording) are aggregated as trials (:func:`replay.trajectory.trials.aggregate`)."""

    groups = {}
    for shown, board in boards:
        for row in board:
            if str(row.get("filter", "")).startswith("recorded:"):
                groups.setdefault((row["filter"], row.get("task", "")), []).append((shown, row))
    out = []
    for (name, _task), members in groups.items():
        agg = aggregate([dict(r, params="{}") for _, r in members])
        shown = "+".join(dict.fromkeys(s for s, _ in members))
        for k in [k for k in aggregated_keys(members[0][1]) if not k.endswith(("_ci95", "_median"))]:
            out.append(
                {
                    "results": shown,
                    "estimate": name[len("recorded:") :],
                    "length": "",
                    "metric": k,
                    "trials": agg["runs"],
                    "mean": finite(agg[k]),
                    "median": finite(agg[f"{k}_median"]),
                    "ci95": finite(agg[f"{k}_ci95"]),
                    "lost": agg["lost"],
                }
            )
    return out


def rows(archives, table: str = "stats", boards=()) -> list[dict]:
    """The rows of ``table`` (module docstring) over the archives, in the order given; ``boards``: leaderboards
    of eval/campaign outputs (:func:`across`; the trials table only)."""
    if table not in TABLES:
        raise ReplayError(f"--table {table!r}: expected one of {', '.join(TABLES)}")
    if boards and table == "stats":
        raise ReplayError(
            f"{boards[0][0]}: a replay eval or campaign output, not a results archive: tabulate it "
            "with replay leaderboard, or aggregate its recorded estimates across recordings with "
            "replay res --table trials"
        )
    out = stats_rows(archives) if table == "stats" else trials_rows(archives) + across(boards)
    if not out:
        raise ReplayError(
            "--table trials: no trial set in these results (saved with replay score --trials)"
            if table == "trials"
            else "no statistics in these results"
        )
    return out


def _cell(v, digits: int) -> str:
    if isinstance(v, float):
        return "nan" if not math.isfinite(v) else f"{v:.{digits}g}"
    return str(v)


def _latex(s: str) -> str:
    for a, b in (
        ("\\", r"\textbackslash{}"),
        ("&", r"\&"),
        ("%", r"\%"),
        ("$", r"\$"),
        ("#", r"\#"),
        ("_", r"\_"),
        ("{", r"\{"),
        ("}", r"\}"),
        ("~", r"\textasciitilde{}"),
        ("^", r"\^{}"),
    ):
        s = s.replace(a, b) if a != "\\" else s.replace(a, "\0")
    return s.replace("\0", r"\textbackslash{}")


def render(rows_: list[dict], fmt_: str, digits: int = 6) -> str:
    """``rows_`` as CSV (every digit), Markdown or LaTeX (``digits`` significant digits); columns that are
    empty in every row are left out of Markdown and LaTeX."""
    cols = list(rows_[0])
    if fmt_ == "csv":
        return csv_text(rows_, cols)
    cols = [c for c in cols if any(r.get(c, "") != "" for r in rows_)]
    body = [[_cell(r.get(c, ""), digits) for c in cols] for r in rows_]
    if fmt_ == "md":
        lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
        return "\n".join(lines + ["| " + " | ".join(x.replace("|", "\\|") for x in b) + " |" for b in body]) + "\n"
    if fmt_ == "latex":
        spec = "".join("l" if not isinstance(rows_[0].get(c), (int, float)) else "r" for c in cols)
        lines = [f"\\begin{{tabular}}{{{spec}}}", "\\hline", " & ".join(_latex(c) for c in cols) + " \\\\", "\\hline"]
        lines += [" & ".join(_latex(x) for x in b) + " \\\\" for b in body]
        return "\n".join(lines + ["\\hline", "\\end{tabular}"]) + "\n"
    raise ReplayError(f"--format {fmt_!r}: expected one of {', '.join(FORMATS)}")
