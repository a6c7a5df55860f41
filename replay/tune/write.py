"""What ``replay tune`` writes and prints: a ``tuned.toml`` per filter (:func:`write_tuned`) and the
board (:func:`format_board`)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import tomli_w

from replay.util.files import write_bytes
from collections import Counter
from replay.scoring.marks import marks


def write_tuned(t, out: Path, rows) -> dict:
    """``tuned.toml``: the tuned configurations on the test data as a campaign file (``replay
    campaign run`` and ``replay eval --tuned`` take it). Filters tuned to different task
    parameters cannot share one file: then one ``tuned-<filter>.toml`` each."""
    tuned = [r for r in rows if r["label"].endswith("(tuned)")]
    if not tuned:
        return {}
    groups: dict = {}
    for r in tuned:
        key = json.dumps(r["_test"][0].task_params, sort_keys=True)
        groups.setdefault(key, []).append(r)
    files = {}
    for i, (key, rs) in enumerate(groups.items()):
        path = out / ("tuned.toml" if len(groups) == 1 else f"tuned-{rs[0]['filter']}.toml")
        write_bytes(path, _toml(t, rs, json.loads(key)).encode())
        files["tuned" if len(groups) == 1 else f"tuned-{rs[0]['filter']}"] = path
    return files


def _toml(t, rows, task_params: dict) -> str:
    """The campaign file of ``rows`` (written by tomli-w), under two comment lines naming its origin."""
    head = (
        "# written by replay tune: the tuned configurations on the held-out data\n"
        f"# tuned on {rows[0]['tuned_on']}; objective {t.objective}; trials per filter: "
        + ", ".join(f"{r['filter']} {r['trials']}" for r in rows)
        + "\n"
    )
    campaign = {"name": "tuned", "runs": t.runs, "seed": rows[0]["_test"][0].seed, "alignment": t.alignment}
    if t.data_dir:
        campaign["data_dir"] = str(Path(t.data_dir).resolve())
    datasets = []
    for d, p in t.split.test:
        datasets.append({"id": d, "tasks": [t.task], **({"params": p} if p else {})})
        if t.first is not None:
            datasets[-1]["first"] = t.first
    doc = {
        "campaign": campaign,
        "dataset": datasets,
        "task": {t.task: task_params},
        "filter": [{"name": r["filter"], "params": r["_test"][0].filter_params} for r in rows],
    }
    return head + tomli_w.dumps(_no_none(doc))


def _no_none(v):
    """``v`` without the keys whose value is None (TOML has no null: an unset parameter is left out)."""
    if isinstance(v, dict):
        return {k: _no_none(x) for k, x in v.items() if x is not None}
    if isinstance(v, (list, tuple)):
        return [_no_none(x) for x in v]
    return v


def format_board(rows) -> str:
    """The leaderboard as printed: one line per row (default and tuned of each filter)."""
    head = ["filter", "tuned_on", "objective", "trials", "train", "test", "pos_rmse", "lost", "params"]
    body = []
    for r in rows:
        body.append(
            [
                r["label"] + (" (not ranked)" if _marked(r) else ""),
                r["tuned_on"],
                r["objective"],
                str(r["trials"]),
                _num(r["train_score"]),
                _num(r["test_score"]),
                _num(r["pos_rmse"]),
                f"{r['lost']}/{r['runs']}",
                _short(r),
            ]
        )
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    line = lambda cells: "  ".join(c.ljust(w) for c, w in zip(cells, widths)).rstrip()
    return "\n".join([line(head), *(line(b) for b in body)])


def board_notes(rows, failed: dict | None = None) -> list[str]:
    """The lines under the board: rows that are not a filter's error (never moving, scored against
    an input: :func:`replay.scoring.summary.marks`), tuned rows worse than their defaults on the
    held-out data (and which row is better), and why trials scored infinity (``failed``: filter ->
    a reason per such trial)."""
    out = [f"{r['label']}: not ranked: {m}" for r in rows for m in marks(r)]
    kinds = sorted({str(r["reference"]) for r in rows if r.get("reference")})  # issue 35: on every table
    shares = sorted({str(r["reference_shares"]) for r in rows if r.get("reference_shares")})
    out[:0] = [f"reference: {', '.join(kinds)}"] * bool(kinds) + [
        f"reference shares a source with a fed input: {s}" for s in shares
    ]
    pairs = {}
    for r in rows:
        if r["label"].endswith(("(default)", "(tuned)")):
            pairs.setdefault(r["filter"], {})[r["label"].rsplit(" ", 1)[1]] = r
    worse = []
    for name, p in pairs.items():
        d, t = p.get("(default)"), p.get("(tuned)")
        if d is None or t is None or not _worse(t["test_score"], d["test_score"]):
            continue
        worse.append(name)
        out.append(
            f"{name}: tuning made it worse on the held-out data (test {_num(t['test_score'])} against "
            f"{_num(d['test_score'])} for the defaults; training {_num(t['train_score'])} against "
            f"{_num(d['train_score'])}): the better row is {d['label']}"
        )
    if worse and len(worse) == len(pairs):
        out.append(
            "every tuned filter is worse on the held-out data than its defaults: the better rows are "
            + ", ".join(pairs[n]["(default)"]["label"] for n in worse)
            + " (the tuned.toml written holds the tuned settings all the same)"
        )
    for name, why in (failed or {}).items():
        counts = ", ".join(f"{k} ({n}x)" if n > 1 else k for k, n in Counter(why).items())
        out.append(f"{name}: {len(why)} trial(s) failed (the progress line's 'failed'), scored infinity: {counts}")
    return out


def _worse(tuned, default) -> bool:
    try:
        return float(tuned) > float(default)
    except (TypeError, ValueError):
        return False


def _marked(r) -> bool:
    return bool(marks(r))


def _short(r) -> str:
    if r.get("_params") is None:
        return "-"
    p = r["_params"]
    return ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in p.items()) or "defaults"


def _num(v) -> str:
    try:
        v = float(v)
    except (TypeError, ValueError):
        return str(v)
    return f"{v:.4f}" if math.isfinite(v) else str(v)
