"""``replay report DIR`` on a tune directory: per filter the optimisation history, the parameter
importances (:func:`optuna.importance.get_param_importances`, fANOVA) and the train-versus-test gap.

Writes ``history_<filter>.png``, ``importance_<filter>.png`` and ``report.html`` (images embedded)
into ``DIR/report`` (or ``out``).
"""

from __future__ import annotations

import base64
import csv
import html
import json
import math
from pathlib import Path

from replay.util.errors import ReplayError
from replay.outputs import plots
from replay.outputs.report import STYLE
from . import study as studies
import optuna


def is_tune_dir(d: Path) -> bool:
    return (Path(d) / "study.db").is_file() and (Path(d) / "tune.json").is_file()


def make_report(d: Path, out: Path | None = None) -> Path:
    d = Path(d)
    out = Path(out) if out else d / "report"
    out.mkdir(parents=True, exist_ok=True)
    try:
        asked = json.loads((d / "tune.json").read_text())
        with open(d / "leaderboard.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
    except (OSError, ValueError) as err:
        raise ReplayError(f"{d}: not a finished replay tune directory ({err})") from None
    store = studies.storage(d)
    parts = [
        f"<h1>replay tune report: {html.escape(str(d))}</h1>",
        f"<p>objective <b>{html.escape(asked['objective'])}</b>, {asked['trials']} trials per filter; "
        f"tuned on {html.escape(str(asked['tuned_on']))}, tested on {html.escape(str(asked['tested_on']))}"
        + (f"; <b>OVERLAP: {html.escape(str(asked['overlap']))}</b>" if asked.get("overlap") else "")
        + "</p>",
        "<h2>Train versus test</h2>",
        _gap_table(rows),
    ]
    for name in asked["filters"]:
        try:
            st = optuna.load_study(study_name=name, storage=store)
        except Exception as err:  # noqa: BLE001 — a damaged file: one line
            raise studies.damaged(d / "study.db", err) from None
        studies.read_back(st, (asked.get("space") or {}).get(name), d / "study.db")
        done = studies.complete(st)[: asked["trials"]]
        if not done:
            continue
        parts.append(f"<h2>{html.escape(name)}</h2>")
        fig, ((ax,),) = plots.figure(figsize=(7, 3.5))
        xs = [t.number for t in done]
        ys = [t.value if math.isfinite(t.value) else float("nan") for t in done]
        best, low = [], math.inf
        for v in ys:
            low = min(low, v) if math.isfinite(v) else low
            best.append(low)
        ax.plot(xs, ys, "o", ms=3, label="trial")
        ax.plot(xs, best, "-", label="best so far")
        ax.set_xlabel("trial")
        ax.set_ylabel(asked["objective"])
        ax.legend()
        parts.append(_embed(plots.save(fig, out / f"history_{name}.png"), f"optimisation history of {name}"))
        try:
            imp = optuna.importance.get_param_importances(st) if len(done) > 1 else {}
        except (RuntimeError, ValueError):  # one distinct value, or a single parameter: no importance
            imp = {}
        if imp:
            fig, ((ax,),) = plots.figure(figsize=(7, 0.6 + 0.4 * len(imp)))
            ax.barh(list(imp)[::-1], list(imp.values())[::-1])
            ax.set_xlabel("importance (fANOVA)")
            parts.append(_embed(plots.save(fig, out / f"importance_{name}.png"), f"parameter importances of {name}"))
    page = (
        f"<!doctype html><html><head><meta charset='utf-8'><title>replay tune report: {html.escape(d.name)}"
        f"</title><style>{STYLE}</style></head><body>\n" + "\n".join(parts) + "\n</body></html>\n"
    )
    path = out / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def _embed(png: Path, caption: str) -> str:
    b64 = base64.b64encode(Path(png).read_bytes()).decode()
    return (
        f"<figure><img alt='{html.escape(caption)}' src='data:image/png;base64,{b64}'><figcaption>"
        f"{html.escape(caption)}</figcaption></figure>"
    )


def _gap_table(rows) -> str:
    head = ["label", "tuned_on", "trials", "train_score", "test_score", "gap", "pos_rmse", "params"]
    body = []
    for r in rows:
        try:
            gap = f"{float(r['test_score']) - float(r['train_score']):+.4g}"
        except ValueError:
            gap = ""
        cells = [
            r["label"],
            r["tuned_on"],
            r["trials"],
            r["train_score"],
            r["test_score"],
            gap,
            r["pos_rmse"],
            r["params"],
        ]
        body.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells) + "</tr>")
    return (
        "<table><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>" + "".join(body) + "</table>"
        "<p>gap: test score minus training score (the objective on held-out data minus where it was tuned).</p>"
    )
