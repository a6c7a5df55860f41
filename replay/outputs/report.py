"""``replay report DIR``: figures and one self-contained HTML page for a result directory.

Works on a campaign directory (``units/``, :mod:`replay.campaign.store`) and on a ``replay
eval`` output directory (``estimates/<filter>.csv.gz``, ``leaderboard.csv``,
``manifest.json``; see :mod:`replay.outputs.files`); :mod:`replay.outputs.report_data` reads them.

The page starts with a summary (per dataset x task: the lowest mean position RMSE with its
95 % interval, the filters tied with it, the runner-up with the paired difference, and the
flags: collapsed covariance, lost tracks, divergences) and a legend. Then, per dataset x task,
its leaderboard (rounded, with flags), its paired comparisons (a difference below
:data:`~replay.outputs.report_tables.TIE` is a tie) and the figures of
:mod:`replay.outputs.report_plots`, each also written as a PNG:

* ``trajectory_<n>.png`` — reference and estimates of run 0 beside the worst run;
* ``error_<n>.png`` — position error over time, one panel per filter: median and 5-95 % band;
* ``metrics_<n>.png`` — one panel per leaderboard metric (mean and 95 % interval, with units);
* ``nees_<n>.png``, ``nis_<n>.png`` — average NEES / NIS per step against the 95 %
  chi-square band (campaigns only: an eval directory stores only the covariance diagonal).

One colour per filter on the whole page (:class:`~replay.outputs.palette.Palette`, keyed by
filter name), masked reference samples and time gaps left as gaps. ``report.html`` embeds
the PNGs (base64) and loads nothing else (its Content-Security-Policy forbids it): one file
to send or archive.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path

from replay.outputs import plots, report_plots, report_tables, robustness
from replay.outputs.palette import Palette
from replay.outputs.report_data import load

STYLE = (
    "body{font-family:sans-serif;margin:2em;max-width:1400px;color:#222}"
    "table{border-collapse:collapse;font-size:12px;margin:0.5em 0 1em}"
    "td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}"
    "td:first-child,th:first-child{text-align:left}table.summary td{text-align:left}"
    "td.best{font-weight:bold}img{max-width:100%}figure{margin:1em 0}"
    "figcaption{font-size:12px;color:#555}"
    ".sw{display:inline-block;width:0.9em;height:0.9em;margin-right:0.35em;vertical-align:-0.1em;"
    "border:1px solid #0003}.legend{font-size:13px}.note{font-size:12px;color:#555}"
)
CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"

CAPTIONS = {
    "trajectory": "Reference (black; gaps where it is masked) and each filter's estimate, run 0 beside the "
    "worst run (the highest median position RMSE over the filters). A recorded estimate is drawn "
    "as scored (after its align fit) through the reference samples it was associated with; with "
    "recorded estimates only, the reference is drawn through those samples.",
    "error": "Position error norm per step: median over the runs (line) and 5-95 % of the runs (band with "
    "thin outlines), one panel per filter; the other filters' medians in grey. Grey spans: reference "
    "masked (nothing scored).",
    "metrics": "Leaderboard metrics: mean over the non-diverged runs with its 95 % Student-t interval.",
    "nees": "Average NEES over the runs per step; grey: the 95 % chi-square band for that many runs. Above "
    "the band: optimistic (covariance too small); below: pessimistic.",
    "nis": "Average NIS over the runs per step (Kalman-family filters) against the 95 % chi-square band "
    "for the measurement dimension of each step.",
}


def page_palette(sections) -> Palette:
    """The page's palette: every configuration label of every section."""
    labels = []
    for sec in sections:
        labels += [str(r.get("label")) for r in sec.rows] + sec.labels
    return Palette(labels)


def build(d) -> tuple[list, Palette, list]:
    """(sections, palette, [(section index, name, Figure)]) of result directory ``d``: the figures
    of the page, not yet written (tests read their colours)."""
    sections = load(Path(d))
    pal = page_palette(sections)
    figs = [(i, name, fig) for i, sec in enumerate(sections) for name, fig in report_plots.section_figures(sec, pal)]
    return sections, pal, figs


def make_report(d: Path, out: Path | None = None) -> Path:
    """Write the PNGs and ``report.html`` for result directory ``d``; returns the HTML path."""
    d = Path(d)
    sections = load(d)
    pal = page_palette(sections)
    out = Path(out) if out else d / "report"
    out.mkdir(parents=True, exist_ok=True)
    parts = [
        f"<h1>replay report: {html.escape(str(d))}</h1>",
        "<h2>Summary</h2>",
        report_tables.summary_table(sections, pal),
        "<p class='note'>Lowest mean position RMSE over the runs per dataset and task, with its 95 % "
        f"interval; filters within {report_tables.TIE:g} m of it are tied. Colours (the same in every "
        "figure):</p>",
        report_tables.legend(pal),
    ]
    for i, sec in enumerate(sections):
        parts += [f"<h2 id='s{i}'>{html.escape(sec.title)}</h2>", report_tables.leaderboard(sec.rows, pal)]
        ref = sorted(
            {(str(r.get("reference")), str(r.get("reference_shares") or "")) for r in sec.rows if r.get("reference")}
        )
        parts += [  # issue 35: where the reference comes from (replay/scoring/provenance.py), on every table
            f"<p class='note'>reference: {html.escape(k)}"
            + (f"; it shares a source with a fed input: {html.escape(sh)}" if sh else "")
            + "</p>"
            for k, sh in ref
        ]
        if sec.paired:
            parts.append(report_tables.paired(sec, pal))
        for name, fig in report_plots.section_figures(sec, pal):
            png = plots.save(fig, out / f"{name}_{i}.png", dpi=100)
            b64 = base64.b64encode(png.read_bytes()).decode()
            parts.append(
                f"<figure><img alt='{name} {html.escape(sec.title)}' src='data:image/png;base64,{b64}'>"
                f"<figcaption>{html.escape(CAPTIONS[name])}</figcaption></figure>"
            )
    parts += _robustness(sections, pal, out)
    page = (
        "<!doctype html><html><head><meta charset='utf-8'>"
        f"<meta http-equiv='Content-Security-Policy' content=\"{CSP}\">"
        f"<title>replay report: {html.escape(d.name)}</title><style>{STYLE}</style></head><body>\n"
        + "\n".join(parts)
        + "\n</body></html>\n"
    )
    path = out / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def _robustness(sections, pal, out: Path) -> list[str]:
    """The robustness sweeps of a campaign (``[[fault]]`` with ``sweep``): each one's table (metric
    per intensity, lost share, the robustness score, the time to recover after an outage) and its
    degradation curves; the tables also in ``robustness.md``."""
    parts, tables = [], []
    for sec in sections:
        for sweep in robustness.sweeps(sec.rows):
            k = len(tables)
            tables.append(robustness.markdown(sweep, series=sec.runs))
            parts += ["<h2>Robustness</h2>"] if k == 0 else []
            parts.append(f"<pre>{html.escape(tables[-1])}</pre>")
            png = plots.save(robustness.figure(sweep, palette=pal), out / f"degradation_{k}.png", dpi=100)
            b64 = base64.b64encode(png.read_bytes()).decode()
            parts.append(
                f"<figure><img alt='degradation {k}' src='data:image/png;base64,{b64}'><figcaption>Degradation "
                "curve: the mean position RMSE over the runs at each intensity, the band its 95 % interval; the "
                "score is the area under the curve divided by the intensity range (lower: more robust)."
                "</figcaption></figure>"
            )
            over_time = robustness.outage_figure(sweep, sec.runs, palette=pal)
            if over_time is not None:
                png = plots.save(over_time, out / f"outage_{k}.png", dpi=100)
                b64 = base64.b64encode(png.read_bytes()).decode()
                parts.append(
                    f"<figure><img alt='outage {k}' src='data:image/png;base64,{b64}'><figcaption>The position "
                    "error over time across the longest outage of the sweep (shaded), median over the runs."
                    "</figcaption></figure>"
                )
    if tables:
        (out / "robustness.md").write_text("\n\n".join(tables) + "\n", encoding="utf-8")
    return parts
