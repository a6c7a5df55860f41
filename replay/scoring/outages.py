"""The end-of-outage errors of an evaluation under the outage / resurfacing protocol
(:mod:`replay.tasks.outages`, ``--task-param score=outages`` of the ``fusion`` task).

Every scored sample is one event: the resurfacing fix after an outage. Per filter, the error at
event k of run r is the position error's norm there, ``e[r, k]``. Per event: its mean over runs
and the half-width of that mean's 95 % Student-t interval over runs (0 for a deterministic
filter on a recording: every run is the same). The headline, per filter: the mean over events of
the per-event means, with its 95 % Student-t interval *across events* (the events are the
independent samples: the runs of a deterministic filter add nothing), the median and the largest.
Two filters are compared event by event (:func:`paired`): the mean of their per-event
differences with its interval across events, called different only when it excludes zero.
"""

from __future__ import annotations

import numpy as np

from .significance import t_interval
from replay.util.files import write_csv

EVENT_COLUMNS = ["filter", "event", "start_s", "end_s", "outage_s", "runs", "error", "error_ci95"]
HEADLINE_COLUMNS = ["filter", "events", "runs", "mean_error", "mean_error_ci95", "median_error", "max_error"]


def is_outages(ev) -> bool:
    """Whether ``ev`` (a :class:`replay.run.evaluation.Evaluation`) was scored under the protocol."""
    return (ev.config.get("task_params") or {}).get("score") == "outages"


def spans(ev) -> list:
    """``[[start, end], ...]`` (s, the recording's time) of each outage, from the task's problem."""
    for res in ev.results:
        for rec in res.records:
            p = rec.problem
            if p is not None and "outages" in getattr(p, "params", {}):
                return [list(s) for s in p.params["outages"]]
    return []


def event_steps(ev) -> np.ndarray:
    """The steps of the events: where the reference holds a resurfacing fix."""
    truth = np.asarray(ev.truths[0], float)
    return np.flatnonzero(np.isfinite(truth).all(axis=1))


def errors(res, steps) -> np.ndarray:
    """(runs, events): the position error's norm of each run of one filter's result at ``steps``
    (NaN for a failed or diverged run)."""
    out = np.full((len(res.errors), len(steps)), np.nan)
    for r, err in enumerate(res.errors):
        pos = np.asarray(err["position"], float)[steps]
        out[r] = np.sqrt(np.sum(pos**2, axis=1))
    return out


def tables(ev) -> tuple[list[dict], list[dict]]:
    """``(events, headline)``: one row per filter and event, and one per filter (module docstring)."""
    steps = event_steps(ev)
    sp = spans(ev)
    t = np.asarray(ev.t, float)
    rows, heads = [], []
    for res in ev.results:
        e = errors(res, steps)
        per = np.nanmean(e, axis=0) if len(e) else np.full(len(steps), np.nan)
        for k, step in enumerate(steps):
            mean, half = t_interval(e[:, k])
            start = sp[k][0] if k < len(sp) else float("nan")
            rows.append(
                dict(
                    filter=res.name,
                    event=k + 1,
                    start_s=start,
                    end_s=float(t[step]),
                    outage_s=float(t[step]) - start,
                    runs=int(np.isfinite(e[:, k]).sum()),
                    error=mean,
                    error_ci95=half,
                )
            )
        mean, half = t_interval(per)
        finite = per[np.isfinite(per)]
        heads.append(
            dict(
                filter=res.name,
                events=len(steps),
                runs=len(e),
                mean_error=mean,
                mean_error_ci95=half,
                median_error=float(np.median(finite)) if len(finite) else float("nan"),
                max_error=float(finite.max()) if len(finite) else float("nan"),
            )
        )
    return rows, heads


def paired(ev, a: str, b: str) -> tuple[float, float, bool]:
    """``(mean, half-width, different)``: filter ``a``'s end-of-outage error minus ``b``'s, event by
    event (each the mean over runs), its 95 % interval across events, and whether it excludes zero."""
    steps = event_steps(ev)
    by = {r.name: r for r in ev.results}
    d = np.nanmean(errors(by[a], steps), axis=0) - np.nanmean(errors(by[b], steps), axis=0)
    mean, half = t_interval(d)
    return mean, half, bool(np.isfinite(half) and abs(mean) > half)


def write(ev, stage) -> None:
    """Under the protocol only: ``outages.csv`` (per filter and event) and ``outages_summary.csv``
    (the headline) into the output directory being staged."""
    if is_outages(ev):
        events, heads = tables(ev)
        write_csv(events, stage / "outages.csv", EVENT_COLUMNS)
        write_csv(heads, stage / "outages_summary.csv", HEADLINE_COLUMNS)


def format_headline(heads: list[dict]) -> str:
    """The headline as printed: per filter the mean end-of-outage error ± its interval across events."""
    lines = [f"{'filter':<14}{'events':>7}{'runs':>6}{'end-of-outage error (m)':>28}{'median':>10}{'max':>10}"]
    for h in heads:
        ci = "" if not np.isfinite(h["mean_error_ci95"]) else f" ± {h['mean_error_ci95']:.2f}"
        lines.append(
            f"{h['filter']:<14}{h['events']:>7}{h['runs']:>6}{h['mean_error']:>20.2f}{ci:<8}"
            f"{h['median_error']:>10.2f}{h['max_error']:>10.2f}"
        )
    lines.append(
        "end-of-outage error: the position error at the first fix after each outage (withheld from every "
        "filter), mean over events ± half-width of its 95 % interval across events; measurements = hold the "
        "last fed fix (outages.csv: per event, with its interval over runs)"
    )
    return "\n".join(lines)
