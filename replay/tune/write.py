"""What ``replay tune`` writes and prints: a ``tuned.toml`` per filter (:func:`write_tuned`) and the
board (:func:`format_board`)."""

from __future__ import annotations

import json
import math
from pathlib import Path

from replay.util.files import write_bytes


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
    lines = [
        "# written by replay tune: the tuned configurations on the held-out data",
        f"# tuned on {rows[0]['tuned_on']}; objective {t.objective}; trials per filter: "
        + ", ".join(f"{r['filter']} {r['trials']}" for r in rows),
        "[campaign]",
        'name = "tuned"',
        f"runs = {t.runs}",
        f"seed = {rows[0]['_test'][0].seed}",
        f'alignment = "{t.alignment}"',
    ]
    if t.data_dir:
        lines.append(f"data_dir = {json.dumps(str(Path(t.data_dir).resolve()))}")
    for d, p in t.split.test:
        lines += ["", "[[dataset]]", f"id = {json.dumps(d)}", f"tasks = [{json.dumps(t.task)}]"]
        if p:
            lines.append("params = " + _inline(p))
        if t.first is not None:
            lines.append(f"first = {t.first}")
    lines += ["", f"[task.{json.dumps(t.task)}]"] + [
        f"{k} = {_val(v)}" for k, v in task_params.items() if v is not None
    ]
    for r in rows:
        lines += [
            "",
            "[[filter]]",
            f"name = {json.dumps(r['filter'])}",
            "params = " + _inline(r["_test"][0].filter_params),
        ]
    return "\n".join(lines) + "\n"


def _val(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf") if not math.isnan(v) else "nan"
    if isinstance(v, dict):
        return _inline(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_val(x) for x in v) + "]"
    return json.dumps(v)


def _inline(d: dict) -> str:
    return "{ " + ", ".join(f"{json.dumps(k)} = {_val(v)}" for k, v in d.items() if v is not None) + " }"


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
    from collections import Counter

    from replay.scoring.marks import marks

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
    from replay.scoring.marks import marks

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
