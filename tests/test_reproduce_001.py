"""Paper 001 reproduction: the water-track DVL of the simulator, the unobservable drift, the document."""

import numpy as np
import pytest

from replay import evaluate  # the API: keywords in, one EvalOptions record built
from replay.sim.sauv_current import make_frame

NOISE_FREE = {"dvl_percent": 0.0, "ahrs_sigma_deg": 0.0, "acc_bias": 0.0, "acc_noise_density": 0.0}


def test_water_track_measures_through_water_velocity():
    bottom = make_frame(np.random.default_rng(3), **NOISE_FREE)
    water = make_frame(np.random.default_rng(3), dvl_track="water", **NOISE_FREE)
    v_ground = bottom.reference["velocity_body"].values
    assert np.allclose(bottom.channels["dvl_velocity"].values, v_ground)
    dvl = water.channels["dvl_velocity"].values
    assert np.abs(dvl[:, 1:]).max() < 1e-9  # through the water the AUV only surges (no roll, no slip)
    assert np.abs(dvl[:, 0] - v_ground[:, 0]).max() > 0.1  # ... and the current is not in it
    # the truth and every other channel are the same; bottom lock is the default, draws unchanged
    assert np.array_equal(water.reference["position"].values, bottom.reference["position"].values)
    assert np.array_equal(water.channels["accel"].values, bottom.channels["accel"].values)
    default = make_frame(np.random.default_rng(3))
    explicit = make_frame(np.random.default_rng(3), dvl_track="bottom")
    assert np.array_equal(default.channels["dvl_velocity"].values, explicit.channels["dvl_velocity"].values)
    assert water.simulation.params.dvl_track == "water"


def test_water_track_error_is_the_integrated_current():
    """With noise-free sensors in water track the UKF's final horizontal error is the current's
    displacement over the mission (north/east are unobservable): within the prior's few metres. One
    run each (two doubled the cost, 15-30 s, for a second draw of the same assertion)."""
    params = dict(NOISE_FREE, dvl_track="water", strength=0.5)
    ev = evaluate("sim/sauv-current", filters=("ukf",), runs=1, seed=0, dataset_params=params)
    for run in range(1):
        from replay.run.pipeline import load_frame

        frame = load_frame(ev.results[0].config, run)
        cur = frame.reference["current"].values
        T = frame.simulation.dt
        shift = np.linalg.norm(T * cur[:-1].sum(axis=0))
        final = ev.results[0].runs[run]["final_err"]
        assert shift > 50
        assert final == pytest.approx(shift, abs=6.0)
    bottom = evaluate(
        "sim/sauv-current", filters=("ukf",), runs=1, seed=0, dataset_params=dict(NOISE_FREE, strength=0.5)
    )
    assert bottom.rows[0]["pos_rmse"] < 0.1 * ev.rows[0]["pos_rmse"]


@pytest.mark.slow
def test_reproduce_001_quick(tmp_path):
    from replay.reproduce.p001 import run
    from replay.reproduce.rules import LABELS
    from replay.util.portable import check_portable

    doc = tmp_path / "001.md"
    evs = run(quick=True, runs=3, doc=doc, quiet=True)
    text = doc.read_text(encoding="utf-8")
    assert text.startswith("# Reproduction of paper 001")
    head = text.split("## Setting")[0]
    assert "## Verdict" in head and "(of 7 claims)" in head
    assert "deviation explained" not in head  # the old vocabulary is gone
    assert sum(head.count(f"**{lab}**") for lab in LABELS) == 7
    for anchor in ("e-primary", "e-observability", "e-premise"):
        assert f'<a id="{anchor}"></a>' in text and f"(#{anchor})" in head
    for section in (
        "## North and east are unobservable",
        "## Baselines at their best",
        "## Every cell",
        "## The premise",
        "## Forgetting factor b",
        "## Ablation",
        "## Relabelled rows",
    ):
        assert section in text
    assert "adapt_means=none" in text and "dvl_track=water" in text and "aukf.forgetting=0.95" in text
    assert "ukf.r_scale=100.0" in text and "ANEES (position, 3 dof)" in text and "**chosen**" in text
    check_portable(text, "001.md")
    assert (tmp_path / "001_traces.png").exists()
    # the numbers behind the verdicts
    floor_w = evs["water noise-free"].rows[0]["pos_rmse"]
    floor_b = evs["bottom noise-free"].rows[0]["pos_rmse"]
    assert floor_w > 40 and floor_b < 6
    main = evs["bottom 0.5"].rows
    assert main[1]["pos_rmse"] > 3 * main[0]["pos_rmse"]  # the paper's AUKF loses in bottom lock
    mis = evs["mistuned"].rows
    assert mis[1]["pos_rmse"] > mis[0]["pos_rmse"] > 40  # R x 100: the AUKF does not help


def test_tuned_ukf_rule_breaks_rmse_ties_by_anees(monkeypatch):
    """The declared rule: lowest mean position RMSE; within 1 % of it, the ANEES closest to 3."""
    from types import SimpleNamespace

    from replay.reproduce import p001
    from replay.util.errors import ReplayError

    s = p001.load()
    Q, R = s["tuning"]["grid"]["q_scale"], s["tuning"]["grid"]["r_scale"]
    rows = {(q, r): {"pos_rmse": 10.0 + q + r, "anees": 50.0} for q in Q for r in R}
    calls = []

    def fake_run_jobs(jobs, runs, seed, data_dir, quiet):  # the grid's evaluations, one fake row per point
        calls.append((len(jobs), {j.runs for j in jobs}, seed))
        return {j.key: SimpleNamespace(rows=[rows[tuple(j.filter_params["ukf"].values())]]) for j in jobs}

    monkeypatch.setattr(p001, "evaluate_jobs", fake_run_jobs)
    rows[Q[0], R[0]].update(pos_rmse=5.0, anees=400.0)
    rows[Q[-1], R[-1]].update(pos_rmse=5.04, anees=3.5)  # within 1 %
    rows[Q[1], R[1]].update(pos_rmse=5.06, anees=3.0)  # 1.2 %: out
    tuned, label, grid = p001.tune(s, 50, 7, None, True)
    assert tuned == {"q_scale": Q[-1], "r_scale": R[-1]}
    assert grid.count("**chosen**") == 1 and label == f"UKF tuned (q × {Q[-1]:g}, r × {R[-1]:g})"
    assert calls == [(len(Q) * len(R), {s["tuning"]["runs"]}, 8)]  # at most 20 runs, on master seed + 1
    rows[Q[2], R[2]].update(pos_rmse=1.0, diverged=1)  # not chosen
    assert p001.tune(s, 3, 0, None, True)[0] == tuned
    for x in rows.values():
        x["pos_rmse"] = float("nan")
    with pytest.raises(ReplayError, match="every grid point of the UKF diverged"):
        p001.tune(s, 3, 0, None, True)


def test_jobs_expand_cells_sweep_and_quick():
    """The TOML's expansion rules: each cell runs every cell_job; sweep jobs get the sweep's runs;
    full-only jobs are left out of the quick document; "tuned" is replaced by the chosen scales."""
    from replay.reproduce import p001

    s = p001.load()
    tuned = {"q_scale": 10.0, "r_scale": 1.0}
    full = {j.key: j for j in p001.jobs(s, False, tuned, 50, 30)}
    quick = {j.key: j for j in p001.jobs(s, True, tuned, 3, 3)}
    cells = [c["key"] for c in s["cell"]]
    assert all(f"{c}{x}" in full for c in cells for x in ("", " QR", " tuned"))
    assert set(full) - set(quick) == {
        "bottom 1.5",
        "bottom 1.5 QR",
        "bottom 1.5 tuned",
        "water 1.5",
        "water 1.5 QR",
        "water 1.5 tuned",
        "bottom b=0.97",
        "bottom b=0.97 QR",
        "water b=0.97",
        "water b=0.97 QR",
    }
    assert full["water 0.5 tuned"].filter_params == {"ukf": tuned}
    assert full["water 0.5 QR"].dataset_params == {"dvl_track": "water", "strength": 0.5}
    assert full["water 0.5 QR"].filter_params == {"aukf": {"adapt_means": "none"}}
    assert (full["bottom 0.5"].runs, full["bottom ablation q̂ only"].runs, full["traces"].runs) == (50, 30, 10)
    assert full["linear"].dataset == "sim/linear" and full["linear"].task_params == {"q": 0.3, "r": 2.0}


def _edited_spec(tmp_path, monkeypatch, *edits):
    """001.toml copied to tmp_path with each (old, new) of ``edits`` replaced once, read instead of the package's."""
    from replay.reproduce import spec

    text = spec.path("001", "toml").read_text(encoding="utf-8")
    for old, new in edits:
        assert old in text
        text = text.replace(old, new, 1)
    (tmp_path / "001.toml").write_text(text, encoding="utf-8")
    monkeypatch.setattr(spec, "PAPERS", tmp_path)


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("at_most = 10", "at_mots = 10", "001.toml: job 'traces': unknown key(s) ['at_mots']"),
        ('paired = ["pos_rmse"]\n', "", "001.toml: table 'floor': missing key(s) ['paired']"),
        ("fb = 1.2", "fbb = 1.2", "001.toml: evidence 'depth, AUKF < 1.2 × UKF': unknown key(s) ['fbb']"),
        ('sweep_runs = 30', 'sweep_run = 30', "001.toml: top level: unknown key(s) ['sweep_run']"),
        (
            '{ suffix = " QR", filters',
            '{ suffix = " QR", filter',
            "001.toml: cell_job ' QR': unknown key(s) ['filter']",
        ),
        ('"water noise-free", "ukf"],\n]', '"water noisefree", "ukf"],\n]', "not declared: ['water noisefree']"),
        ('info = "guards"', 'info = "guard"', "not declared: ['guard']"),
        ('[traces]\njob = "traces"', '[traces]\njob = "trace"', "not declared: ['trace']"),
    ],
)
def test_toml_refuses_unknown_missing_and_undeclared(tmp_path, monkeypatch, old, new, message):
    from replay.reproduce import p001

    _edited_spec(tmp_path, monkeypatch, (old, new))
    with pytest.raises(ValueError) as err:
        p001.load()
    assert message in str(err.value) and "\n" not in str(err.value)


# slow: a reproduction's jobs computed (the quick check keeps the TOML checks)
@pytest.mark.slow
def test_a_row_added_in_the_toml_is_a_row_of_the_document(tmp_path, monkeypatch):
    """An ablation is a TOML edit: a job and a row in its table, no code. Computed in this process
    (REPLAY_WORKERS=1: two worker processes cost 1.6 s of imports; tests/test_verdict.py covers the pool)."""
    from replay.reproduce import p001
    from replay.campaign.longest import evaluate_jobs

    job = (
        '    { key = "linear wrong R, Q̂ only", dataset = "sim/linear", filters = ["aukf"], data = { steps = 2000, '
        'q = 0.3, r = 2.0 }, params = { aukf = { adapt_means = "none", adapt_r = false, r_scale = 100.0 } }, '
        'task = { q = 0.3, r = 2.0 } },\n'
    )
    job_at = '    { key = "linear wrong R, R̂ only"'
    row_at = '    ["AUKF (R̂ only), R̂₀ = R × 100", "linear wrong R, R̂ only", "aukf"],\n'
    row = '    ["AUKF (Q̂ only), R̂₀ = R × 100", "linear wrong R, Q̂ only", "aukf"],\n'
    _edited_spec(tmp_path, monkeypatch, (job_at, job + job_at), (row_at, row_at + row))
    monkeypatch.setenv("REPLAY_WORKERS", "1")
    s = p001.load()
    linear = next(t for t in s["table"] if t["name"] == "linear")
    planned = [j for j in p001.jobs(s, True, {}, 2, 2) if j.key in {r[1] for r in linear["rows"]}]
    assert "linear wrong R, Q̂ only" in [j.key for j in planned]
    out = p001.spec_table(s, evaluate_jobs(planned, 2, 0, quiet=True), linear)
    assert "| AUKF (Q̂ only), R̂₀ = R × 100 |" in out and "aukf.adapt_r=false" in out
    assert out.count("AUKF (Q̂ only), R̂₀ = R × 100") == 3  # its RMSE row, its command, its final estimates


# ---------------------------------------------------------------- figures (synthetic inputs, fast)


def _fake_ev(runs=5, steps=40, seed=0, scale=1.0):
    from types import SimpleNamespace

    rng = np.random.default_rng(seed)
    errors = [
        {"position": scale * rng.standard_normal((steps, 3)), "vx": 0.1 * scale * rng.standard_normal(steps)}
        for _ in range(runs)
    ]
    return SimpleNamespace(results=[SimpleNamespace(errors=errors)] * 2)


def test_error_figures_one_panel_per_filter_with_units_rmse_and_band():
    from replay.outputs.palette import colour
    from replay.outputs.plots import abs_errors, rmse_figures
    from replay.reproduce.p001 import load

    quantities = load()["quantities"]

    t = np.arange(40) * 0.5
    ev, qr = _fake_ev(), _fake_ev(seed=1, scale=2.0)
    errs = {
        lab: abs_errors(e.results[i].errors, quantities)
        for lab, e, i in (("UKF", ev, 0), ("AUKF (paper)", ev, 1), ("AUKF (Q̂, R̂)", qr, 0))
    }
    signed = np.stack([e["position"] for e in qr.results[0].errors])
    assert np.array_equal(errs["AUKF (Q̂, R̂)"]["east"], np.abs(signed[:, :, 1]))
    figs = rmse_figures(t, errs, [q[:3] for q in quantities], "001, bottom-lock DVL, current 0.5 m/s")
    assert list(figs) == ["north", "east", "depth", "vx"]
    for key, unit in (("north", "(m)"), ("depth", "(m)"), ("vx", "(m/s)")):
        axes = [ax for ax in figs[key].axes if ax.get_visible()]
        assert len(axes) == 3  # one panel per filter
        assert axes[0].get_ylabel().endswith(unit) and axes[0].get_xlabel() == "t (s)"
        assert [ax.get_title().split(":")[0] for ax in axes] == list(errs)
        assert all("RMSE over 5 runs, band 5-95 %" in ax.get_title() for ax in axes)
        assert "001, bottom-lock DVL, current 0.5 m/s" in figs[key]._suptitle.get_text()
    # the Q̂R̂ panel: its line is the RMSE over the runs at each step, its band spans the runs' 5-95 %
    ax = figs["east"].axes[2]
    line = next(ln for ln in ax.get_lines() if ln.get_label() == "AUKF (Q̂, R̂)")
    assert np.allclose(line.get_ydata(), np.sqrt(np.mean(signed[:, :, 1] ** 2, axis=0)))
    ukf = next(ln for ln in figs["east"].axes[0].get_lines() if ln.get_label() == "UKF")
    paper = next(ln for ln in figs["east"].axes[1].get_lines() if ln.get_label() == "AUKF (paper)")
    assert ukf.get_color() == colour("ukf") and len({ukf.get_color(), paper.get_color(), line.get_color()}) == 3
    band = [c for c in ax.collections if c.get_gid() == "AUKF (Q̂, R̂)"]
    assert len(band) == 1
    ys = band[0].get_paths()[0].vertices[:, 1]
    lo, hi = np.percentile(np.abs(signed[:, :, 1]), (5, 95), axis=0)
    assert np.isclose(ys.min(), lo.min()) and np.isclose(ys.max(), hi.max())


def test_traces_figure_median_and_band_with_units():
    from types import SimpleNamespace

    from replay.reproduce.p001 import load, traces_figure

    rng = np.random.default_rng(3)
    hist = [{"p": rng.standard_normal((30, 2)), "q": rng.standard_normal((30, 3))} for _ in range(6)]
    fig = traces_figure(np.arange(31.0), [SimpleNamespace(info={"history": h}) for h in hist], load()["traces"])
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == ["p̂ depth (m)", "p̂ forward velocity (m/s)", "q̂ north (m/step)", "q̂ east (m/step)"]
    line = next(ln for ln in fig.axes[2].get_lines() if ln.get_label() == "AUKF (paper)")
    assert np.allclose(line.get_xdata(), np.arange(1.0, 31.0))  # the last 30 times
    assert np.allclose(line.get_ydata(), np.median([h["q"][:, 0] for h in hist], axis=0))
    assert len([c for c in fig.axes[2].collections if c.get_gid() == "AUKF (paper)"]) == 1  # the band
    assert "6 runs" in fig._suptitle.get_text()
