"""`replay report`: one colour per filter, legible bands, chi-square bands, gaps, worst run, tables.

The figure tests build sections in memory (no filter runs) and read the figures' data.
"""
import base64
import gzip
import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli import main
from replay.outputs import palette, plots, report_plots, report_tables
from replay.outputs.palette import FIXED, Palette
from replay.outputs.report import build, page_palette
from replay.outputs.report_data import Section, worst_run

NAN = float("nan")
LABELS = ("pf", "ekf", "ukf(alpha=0.5)", "ukf(alpha=1.0)")
MASK = slice(20, 30)  # reference masked on these steps
GAP = 45  # a 5 s time gap before this step (the median step is 0.1 s)


def _section(dataset="sim/x", labels=LABELS, runs=4, n=60, axes=("x", "y", "z"), worst=2, seed=0):
    """A campaign-like section: NEES for all, NIS for all but pf (its nis_dof is 0, as a PF records)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    t[GAP:] += 5.0
    truth = np.column_stack([np.cos(t), np.sin(t), -t])[:, :len(axes)]
    ref = truth.copy()
    ref[MASK] = NAN
    sec = Section(dataset, "task", tuple(axes))
    for k, lab in enumerate(labels):
        sec.runs[lab], sec.metrics[lab] = {}, {}
        for r in range(runs):
            err = rng.normal(0, 0.1 * (1 + k) * (10 if r == worst else 1), truth.shape)
            err[MASK] = NAN
            dof = np.where(np.isfinite(err).all(axis=1), 0 if lab == "pf" else 3, 0)
            nis = np.where(dof > 0, rng.chisquare(3, n), NAN)
            nees = rng.chisquare(3, n) * (1e200 if lab == "pf" else 1)  # a collapsed PF
            sec.runs[lab][r] = {"t": t, "pos": truth + np.nan_to_num(err), "ref": ref, "err": err,
                                "valid": np.isfinite(err).all(axis=1), "nees": nees, "nis": nis,
                                "nis_dof": dof.astype(float)}
            sec.metrics[lab][r] = {"pos_rmse": float(np.sqrt(np.nanmean(np.sum(err ** 2, axis=1))))}
        sec.rows.append({"dataset": dataset, "task": "task", "label": lab, "runs": runs, "diverged": 0, "lost": 0,
                         "lost_share": 0.0, "pos_rmse": 0.1 * (1 + k), "pos_rmse_ci95": 0.01, "ate": 0.1 + k,
                         "ate_ci95": 0.02, "anees": 1.15e235 if lab == "pf" else 3.1,
                         "anees_flag": "collapsed" if lab == "pf" else "consistent", "us_per_step": 4.0 + k})
    return sec


def _page():
    secs = [_section(), _section("sim/y", labels=("ekf", "ckf", "pf"), axes=("north", "east"), seed=1),
            _section("sim/z", labels=("ukf(alpha=0.5)", "ekf"), axes=("depth",), seed=2)]
    pal = page_palette(secs)
    return secs, pal, [(i, name, fig) for i, s in enumerate(secs) for name, fig in report_plots.section_figures(s, pal)]


@pytest.fixture(scope="module")
def page():
    return _page()


def test_one_colour_per_filter_across_every_figure(page):
    secs, pal, figs = page
    colours = plots.artist_colours([f for *_, f in figs])
    labels = {lab for s in secs for lab in s.labels}
    assert labels <= set(colours)
    for lab in labels:
        assert colours[lab] == {pal.colour(lab)}, lab  # lines, bands, points: one colour on the whole page
    assert len({pal.colour(lab) for lab in labels}) == len(labels)  # and no two filters share one
    assert colours["ekf"] == {FIXED["ekf"]} and colours["pf"] == {FIXED["pf"]}  # fixed by name, page or not
    # the figures that draw filters: every one of them names its filters by gid
    for i, name, fig in figs:
        drawn = {a.get_gid() for ax in fig.axes for a in ax.get_children()}
        assert set(secs[i].labels) <= drawn or name in ("nis",), (i, name)


def test_variants_keep_their_filters_hue_and_unknown_names_never_collide():
    import colorsys

    pal = Palette(["ukf(alpha=0.5)", "ukf(alpha=1.0)", "ukf(alpha=2.0)", "ekf"])
    hues = [colorsys.rgb_to_hls(*(int(c[k:k + 2], 16) / 255 for k in (1, 3, 5)))[0]
            for c in (pal.colour(f"ukf(alpha={a})") for a in ("0.5", "1.0", "2.0"))]
    assert max(hues) - min(hues) < 0.02 and len({pal.colour(f"ukf(alpha={a})") for a in ("0.5", "1.0", "2.0")}) == 3
    assert pal.linestyle("ukf(alpha=0.5)") != pal.linestyle("ukf(alpha=1.0)") and pal.linestyle("ekf") == "-"
    names = [f"mine{i}" for i in range(40)]
    same = [n for n in names if palette.colour(n) == palette.colour(names[0])]
    assert len(same) >= 2  # two unknown names hash to the same spare colour ...
    assert len({Palette(same).colour(n) for n in same}) == len(same)  # ... and a page separates them
    assert palette.colour("EKF") == FIXED["ekf"] and len(set(FIXED.values())) == len(FIXED)


def test_error_bands_one_panel_per_filter(page):
    secs, pal, figs = page
    fig = next(f for i, n, f in figs if i == 0 and n == "error")
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert len(panels) == len(LABELS)
    for ax, lab in zip(panels, LABELS):
        bands = [c for c in ax.collections if c.get_gid() == lab]
        assert len(bands) == 1 and lab in ax.get_title()  # one band per panel: they never merge
        assert ax.get_ylabel() in ("position error (m)", "") and ax.get_yscale() == "log"


def test_chi2_band_on_every_nees_and_nis_plot(page):
    from replay.scoring.metrics import chi2_band

    secs, pal, figs = page
    cons = [(i, n, f) for i, n, f in figs if n in ("nees", "nis")]
    assert len(cons) == 6  # NIS too, although pf (drawn first, no NIS) leads the section
    for i, name, fig in cons:
        band = [a for a in fig.axes[0].get_children() if a.get_gid() == "chi2"]
        assert len(band) == 1, (i, name)
    lo, hi = plots.chi2_limits(3, 4)
    assert np.allclose((lo, hi), chi2_band(3, 4))
    nees = next(f for i, n, f in figs if i == 0 and n == "nees").axes[0]
    y = np.concatenate([ln.get_ydata() for ln in nees.lines if ln.get_gid() == "pf"])
    assert np.nanmax(y) == report_plots.CLIP[1]  # a collapsed PF's 1e200 is clipped, and flagged:
    assert any(t.get_text() == "pf (collapsed)" for t in nees.get_legend().get_texts())


def test_chi2_band_follows_a_varying_dof():
    fig, ax = plots.figure()
    t = np.arange(6.0)
    band = plots.chi2_band(ax[0, 0], t, [0, 1, 1, 3, 3, 0], 10)
    ys = band.get_paths()[0].vertices[:, 1]
    lo1, hi1 = plots.chi2_limits(1, 10)
    lo3, hi3 = plots.chi2_limits(3, 10)
    assert np.isclose(ys, hi3).any() and np.isclose(ys, lo1).any() and not np.isclose(ys, hi1).all()
    assert plots.chi2_band(ax[0, 0], t, np.zeros(6), 10) is None  # no measurement: no band


def test_gaps_stay_gaps(page):
    secs, pal, figs = page
    traj = next(f for i, n, f in figs if i == 0 and n == "trajectory")
    ref = [ln for ln in traj.axes[0].lines if ln.get_gid() == "reference"][0]
    x = np.asarray(ref.get_xdata(), float)
    assert np.isnan(x[MASK]).all() and np.isnan(x).sum() == 10 + 1  # masked samples, plus one NaN in the time gap
    zt = traj.axes[1 if len(traj.axes) == 2 else 2]  # z over time, run 0
    for ln in zt.lines:
        t = np.asarray(ln.get_xdata(), float)
        assert np.isnan(t).sum() == 1 and np.isnan(t[GAP])  # the 5 s without samples is not bridged
    t, y = plots.gaps([0, 1, 2, 10, 11], [1, 2, 3, 4, 5])
    assert np.isnan(t[3]) and list(y[[0, 1, 2, 4, 5]]) == [1, 2, 3, 4, 5]


def test_worst_run_beside_run_0(page):
    secs, pal, figs = page
    assert worst_run(secs[0]) == 2
    traj = next(f for i, n, f in figs if i == 0 and n == "trajectory")
    titles = [ax.get_title() for ax in traj.axes]
    assert "x-y plane, run 0" in titles and any(t.startswith("x-y plane, worst run: 2") for t in titles)
    ned = next(f for i, n, f in figs if i == 1 and n == "trajectory")
    assert ned.axes[0].get_xlabel() == "east (m)" and ned.axes[0].get_ylabel() == "north (m)"  # east right
    depth = next(f for i, n, f in figs if i == 2 and n == "trajectory")
    assert depth.axes[0].get_ylabel() == "depth (m)" and depth.axes[0].yaxis_inverted()


def test_every_plot_has_a_title_and_units(page):
    secs, pal, figs = page
    for i, name, fig in figs:
        assert fig.get_suptitle() or fig.axes[0].get_title(), (i, name)
        for ax in fig.axes:
            if ax.get_visible() and ax.get_xlabel():
                assert re.search(r"\(.+\)$", ax.get_xlabel()), (name, ax.get_xlabel())
            if ax.get_visible() and ax.get_ylabel():
                assert re.search(r"\(.+\)$", ax.get_ylabel()), (name, ax.get_ylabel())
    metrics = next(f for i, n, f in figs if i == 0 and n == "metrics")
    assert {ax.get_xlabel() for ax in metrics.axes if ax.get_visible()} == {
        "position RMSE (m)", "ATE (aligned) (m)", "filter time per step (µs)"}


def test_tables_round_flag_and_call_ties():
    assert report_tables.pm(2.40361, 0.336278) == "2.40 ± 0.34" and report_tables.num(14.75) == "14.8"
    assert report_tables.num(0.011608) == "0.0116" and report_tables.num(81.93) == "81.9"
    assert report_tables.count(20.0) == "20" and report_tables.num(NAN) == "–"
    row = {"anees": 1.15e235, "anees_flag": "collapsed", "anis": 10.04, "anis_flag": "optimistic"}
    assert report_tables.consistency(row, "anees") == "collapsed"
    assert report_tables.consistency(row, "anis") == "10.0 optimistic"
    assert report_tables.verdict(7e-16, 2e-16, "ekf", "ckf").startswith("tie")
    assert report_tables.diff(7e-16, 2e-16) == "|a − b| < 1e-06"
    assert report_tables.verdict(-0.5, 0.1, "ekf", "pf") == "ekf lower"
    assert report_tables.verdict(-0.05, 0.1, "ekf", "pf") == "no significant difference"
    sec = _section(labels=("ekf", "ckf"))
    sec.metrics["ckf"] = {r: {"pos_rmse": v["pos_rmse"] + 7e-16} for r, v in sec.metrics["ekf"].items()}
    assert report_tables.wins(sec, "ekf", "ckf", "pos_rmse") == (0, 0, 4)  # no "wins" on rounding noise


def test_leaderboard_and_summary_tables():
    sec = _section(labels=("pf", "ekf", "ckf"))
    sec.rows[2]["pos_rmse"] = sec.rows[1]["pos_rmse"] + 7e-16  # ckf = ekf (a linear model)
    sec.rows[0].update(lost=2, lost_share=0.7, pos_rmse=0.5)
    sec.paired = [{"a": "ekf", "b": "ckf", "metric": "pos_rmse", "n": "4", "diff": "-7e-16", "diff_ci95": "1e-16"},
                  {"a": "pf", "b": "ekf", "metric": "pos_rmse", "n": "4", "diff": "0.1", "diff_ci95": "0.02"}]
    pal = page_palette([sec])
    page = report_tables.leaderboard(sec.rows, pal)
    assert "<td>2/4*</td>" in page and "<td>collapsed</td>" in page and "e+235" not in page
    assert "<td class=\"best\">0.200 ± 0.010</td>" in page and "<th>position RMSE (m)</th>" in page
    s = report_tables.summary_rows([sec])[0]
    assert s["best"] == "ekf" and s["ties"] == ["ckf"] and s["value"] == "0.200 ± 0.010"
    assert s["note"] == "next: pf 0.500 ± 0.010 m; paired difference -0.100 ± 0.020 m: ekf lower"
    assert "pf: ANEES collapsed" in s["flags"] and "pf: lost 2/4*" in s["flags"]
    paired = report_tables.paired(sec, pal)
    assert "1 significant, 1 ties" in paired and "tie (|a − b| &lt; 1e-06 m)" in paired


def _eval_dir(d, axes=("depth",), filters=("ekf", "pf"), runs=3, n=40):
    """A `replay eval` output written by hand: leaderboard, manifest, estimates."""
    (d / "estimates").mkdir(parents=True)
    rng = np.random.default_rng(0)
    rows = []
    for f in filters:
        head = ["run", "k", "t"] + [f"x{i}" for i in range(len(axes) + 1)] + [f"P{i}{i}" for i in range(len(axes) + 1)]
        head += [f"err_{a}" for a in axes]
        lines = [",".join(head)]
        for r in range(runs):
            for k in range(n):
                err = rng.normal(0, 0.2, len(axes)) if not 10 <= k < 15 else [NAN] * len(axes)
                x = [k * 0.1 + (e if np.isfinite(e) else 0) for e in err] + [1.0]
                lines.append(",".join(map(str, [r, k, k * 0.5, *x, *([0.1] * (len(axes) + 1)), *err])))
        with gzip.open(d / "estimates" / f"{f}.csv.gz", "wt") as fh:
            fh.write("\n".join(lines) + "\n")
        rows.append(f"sim/x,t,{f},{f},{{}},{runs},0,0,0.0,0,0,,0.2,0.01")
    (d / "leaderboard.csv").write_text(
        "dataset,task,filter,label,params,runs,diverged,lost,lost_share,failed,seed,first,pos_rmse,pos_rmse_ci95\n"
        + "\n".join(rows) + "\n")
    (d / "manifest.json").write_text(json.dumps({"config": {"dataset": "sim/x", "task": "t"}}))


def _pngs_in(page):
    return [base64.b64decode(b) for b in re.findall(r"src='data:image/png;base64,([^']+)'", page)]


def test_report_on_a_one_axis_eval_dir(tmp_path):
    _eval_dir(tmp_path / "ev")
    res = CliRunner().invoke(main, ["report", str(tmp_path / "ev"), "-o", str(tmp_path / "r")])
    assert res.exit_code == 0, res.output
    page = (tmp_path / "r" / "report.html").read_text()
    assert len(_pngs_in(page)) == 3 and "Content-Security-Policy" in page  # no NEES/NIS: eval keeps diag(P)
    assert {p.name for p in (tmp_path / "r").glob("*.png")} == {"trajectory_0.png", "error_0.png", "metrics_0.png"}
    assert page.index("<h2>Summary</h2>") < page.index("<h2 id='s0'>")


@pytest.mark.slow
def test_report_on_campaign_and_eval_dirs(tmp_path):
    (tmp_path / "c.toml").write_text(
        '[campaign]\nruns = 4\nbatch = 4\n\n[[dataset]]\nid = "sim/auv-sonar"\nparams = { steps = 25 }\n\n'
        '[[filter]]\nname = "ukf"\n\n[[filter]]\nname = "ekf"\n')
    out = tmp_path / "camp"
    res = CliRunner().invoke(main, ["campaign", "run", str(tmp_path / "c.toml"), "-o", str(out), "-w", "1", "-q"])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["report", str(out)])
    assert res.exit_code == 0, res.output
    page = (out / "report" / "report.html").read_text()
    imgs = _pngs_in(page)
    assert len(imgs) == 5 and all(i.startswith(b"\x89PNG") for i in imgs)
    assert "ukf</td>" in page and "Paired comparisons" in page
    assert {p.name for p in (out / "report").glob("*.png")} == {
        f"{n}_0.png" for n in ("trajectory", "error", "metrics", "nees", "nis")}
    secs, pal, figs = build(out)  # the same figures, read back: one colour per filter on real data
    colours = plots.artist_colours([f for *_, f in figs])
    assert {lab: colours[lab] for lab in ("ekf", "ukf")} == {"ekf": {FIXED["ekf"]}, "ukf": {FIXED["ukf"]}}

    ev = tmp_path / "ev"
    res = CliRunner().invoke(main, ["eval", "sim/auv-sonar", "-f", "ekf,ckf", "--runs", "2", "-o", str(ev)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["report", str(ev), "-o", str(tmp_path / "r")])
    assert res.exit_code == 0, res.output
    page = (tmp_path / "r" / "report.html").read_text()
    assert len(_pngs_in(page)) == 3 and "ckf</td>" in page


def test_report_on_other_dir_is_one_line_error(tmp_path):
    res = CliRunner().invoke(main, ["report", str(tmp_path)])
    assert res.exit_code == 2 and "not a result directory" in res.output
