"""Paper 003 reproduction: what the sweeps cover, α = 1 is the PF, the document."""

import numpy as np
import pytest

from replay import evaluate  # the API: keywords in, one EvalOptions record built


SIGMA1 = 0.4 * np.pi / 180  # 003 §4.1


def test_plan_covers_the_regimes_where_alpha_could_matter():
    from replay.reproduce.p003 import T, plan

    everything = plan(4, 50)
    jobs = [j for j in everything if not j.key.startswith("tune|")]
    ns = {p.get("n_particles") for j in jobs for p in j.filter_params.values()}
    assert {50, 100, 200, 500, 1000} <= ns
    accel = {j.dataset_params.get("accel_sigma") for j in jobs} - {None}
    assert min(accel) <= 0.03 and max(accel) >= 0.3  # and 1 (ours) in the N sweep
    ratios = {round(j.dataset_params["sigma2"] / SIGMA1) for j in jobs if "sigma2" in j.dataset_params}
    eps = {j.dataset_params["eps"] for j in jobs if "eps" in j.dataset_params}
    assert max(ratios) == 10 and {0.05, 0.1, 0.3} <= eps
    assert {j.task_params.get("eps") for j in jobs} >= {0.0, 1.0}  # mismatched Gaussian likelihoods
    assert any(j.filter_params.get("pf", {}).get("roughening") for j in jobs)  # impoverishment baseline
    assert len({j.key for j in jobs}) == len(jobs)
    # the verdicts' rows run on the document's seed and three fresh ones; the tuning on other seeds
    assert {j.seed for j in jobs if j.key.startswith("printed|a=0.75|")} == set(T["seeds"])
    tune = [j for j in everything if j.key.startswith("tune|")]
    assert {j.seed for j in tune}.isdisjoint({j.seed for j in jobs})
    assert len(tune) == 2 * sum(len(g["values"]) for g in T["grid"].values())
    assert {j.runs for j in jobs} == {4} and {j.runs for j in tune} == {50}


def test_alpha_one_is_the_bootstrap_pf():
    """WF-PF with α = 1 is the PF bit for bit where the 1e-99 floor does not bind (same generator;
    through ``replay eval`` the two differ by their filter streams, seeded by the filter's name)."""
    from replay.filters.p003.wfpf import WeightFactorPF
    from replay.filters.pf import ParticleFilter
    from replay.run.pipeline import build_problem

    ev = evaluate("sim/uav-formation", filters=("pf",), runs=1, seed=2)
    pb = build_problem(ev.results[0].config, 0)
    a = ParticleFilter(n_particles=200).run(pb.model, pb.z, pb.x0, pb.P0, rng=np.random.default_rng(7))
    b = WeightFactorPF(n_particles=200, alpha=1.0).run(pb.model, pb.z, pb.x0, pb.P0, rng=np.random.default_rng(7))
    assert np.array_equal(a.x, b.x)


def test_core_gaussian_likelihood_is_mismatched_to_strong_glint():
    """A PF that assumes the thermal core only loses against the one that knows the glint."""
    data = {"sigma2": 5 * 0.4 * np.pi / 180, "eps": 0.3}
    right = evaluate(
        "sim/uav-formation",
        filters=("pf",),
        runs=8,
        seed=0,
        dataset_params=data,
        filter_params={"pf": {"n_particles": 100}},
    )
    core = evaluate(
        "sim/uav-formation",
        filters=("pf",),
        runs=8,
        seed=0,
        dataset_params=data,
        filter_params={"pf": {"n_particles": 100}},
        task_params={"eps": 0.0},
    )
    assert core.rows[0]["pos_rmse_median"] > 1.3 * right.rows[0]["pos_rmse_median"]


@pytest.mark.slow
def test_reproduce_003_quick(tmp_path):
    from replay.reproduce.p003 import run
    from replay.util.portable import check_portable

    doc = tmp_path / "003.md"
    evs = run(quick=True, runs=2, doc=doc, quiet=True)
    text = doc.read_text(encoding="utf-8")
    assert text.startswith("# Reproduction of paper 003")
    head = text.split("## Setting")[0]
    assert "## Verdict" in head and "(of 7 claims)" in head
    for section in (
        "## Printed setting",
        "## Why no effect can show",
        "## Where, if anywhere, α < 1 helps",
        "## Distinct particles after resampling",
        "## Replication on fresh seeds",
        "## Baselines at their best",
        "## Sweep of the particle count N",
        "## Sweep of the process noise",
        "## Sweep of the glint contrast",
        "## Mismatched Gaussian likelihood",
        "## Relabelled rows",
    ):
        assert section in text
    # α < 1 keeps more distinct particles even on 2 runs per seed (about +5 % of N at α = 0.75)
    row = next(ln for ln in head.splitlines() if ln.startswith("| α < 1 keeps more distinct"))
    assert "**exploratory**" in row and "post hoc" in row  # holds, but its rule is post hoc: capped
    assert "drifts (grows over the run): reproduced → **" in text
    assert "--task-param eps=0.0" in text and "-p pf.roughening=0.2" in text
    assert "excess kurtosis is 0.48" in text
    check_portable(text, "003.md")
    # the figures: one PNG per axis beside the document, shown by the document
    assert sorted(p.name for p in tmp_path.iterdir()) == ["003.md", "003_rmse_x.png", "003_rmse_y.png"]
    assert "![x position error over time, printed setting](003_rmse_x.png)" in text
    assert "![y position error over time, printed setting](003_rmse_y.png)" in text
    # UKF and EKF are baselines of the printed setting, on the same runs as the PF
    assert [evs[f"printed|{r}|0"].results[0].name for r in ("pf", "ukf", "ekf")] == ["pf", "ukf", "ekf"]
    assert all(evs[f"printed|{r}|0"].rows[0]["diverged"] == 0 for r in ("pf", "a=0.75", "ukf"))


FILTERS = (("PF", 0), ("WF-PF", 1), ("UKF", 2))  # label, result index of the fake evaluation


def _fake_printed(runs=7, steps=30):
    from types import SimpleNamespace

    rng = np.random.default_rng(4)
    signed = [rng.standard_normal((runs, steps, 4)) * (i + 1) for i in range(3)]
    ev = SimpleNamespace(
        t=np.arange(float(steps)), results=[SimpleNamespace(errors=[{"position": r[:, :2]} for r in s]) for s in signed]
    )
    return ev, signed


def test_error_figures_one_panel_per_filter_with_units_and_band():
    from replay.outputs.plots import rmse_curve, rmse_figures
    from replay.reproduce.p003 import T, run_errors

    ev, signed = _fake_printed()
    errs = {label: run_errors(ev, i) for label, i in FILTERS}
    # the peaks the document prints come from the same arrays: RMSE of |e| equals RMSE of e
    assert np.array_equal(rmse_curve(errs["UKF"]["y"]), rmse_curve(signed[2][:, :, 1]))
    fig = rmse_figures(ev.t, errs, T["drift"]["axes"], "003, printed setting")["y"]  # as the document draws them
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title().split(":")[0] for ax in axes] == ["PF", "WF-PF", "UKF"]
    assert axes[0].get_ylabel() == "y position error (m)" and axes[1].get_xlabel() == "t (s)"
    line = next(ln for ln in axes[1].get_lines() if ln.get_label() == "WF-PF")
    assert np.allclose(line.get_ydata(), np.sqrt(np.mean(signed[1][:, :, 1] ** 2, axis=0)))
    assert len([c for c in axes[1].collections if c.get_gid() == "WF-PF"]) == 1  # the 5-95 % band
    assert "7 runs" in fig._suptitle.get_text()


def _table(edit=None):
    """The parsed replay/papers/003.toml, its text changed by ``edit`` (old, new) first."""
    import tomllib

    from replay.reproduce import spec

    text = spec.path("003", "toml").read_text(encoding="utf-8")
    if edit:
        assert edit[0] in text
        text = text.replace(edit[0], edit[1], 1)
    return tomllib.loads(text)


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            ('{ label = "N = 50", table', '{ label = "N = 50", nn = 50, table'),
            r"setting 'N = 50': unknown key\(s\) \['nn'\]",
        ),
        (('pf = { filter = "pf", particles', 'pf = { particles'), r"row 'pf': missing key\(s\) \['filter'\]"),
        (('key = "pf-peak"', 'key = "pf-peak"\nsetings = "printed"'), r"peak: unknown key\(s\) \['setings'\]"),
        (
            ('rough = { row = "rough", param', 'rough = { rows = "rough", param'),
            r"grid 'rough': unknown key\(s\) \['rows'\]",
        ),
        (('family = "paper" }', 'family = "paper", mcnemr = true }'), r"column 'WF-PF 0.75 − PF': unknown key\(s\)"),
        (
            ('dataset = "sim/uav-formation"', 'datasets = "sim/uav-formation"'),
            r"top level: unknown key\(s\) \['datasets'\]",
        ),
        (
            ('"N = 50", table = "N", n = 50, rows = ["a=1.0"', '"N = 50", table = "N", n = 50, rows = ["a=1"'),
            r"setting 'N = 50': names a row",
        ),
        (('"a=0.75", "pf", "growth"]]', '"a=0.75", "pf", "grwoth"]]'), r"evidence 'wf-nodrift': names a row"),
        (("k_strong = { ratio = 10.0, eps", "k_strong = { ratio = 10.0, epsilon"), r"kurtosis 'k_strong': unknown key"),
    ],
)
def test_table_refuses_unknown_and_missing_keys(edit, message):
    """A misspelt, unknown or missing key of the experiments' table (or an undeclared row or value it names) is
    refused with one line naming the file and the entry; the shipped table passes."""
    from replay.reproduce import p003

    assert p003.load(_table())["by_label"]["printed"]["n"] == 1000
    with pytest.raises(ValueError, match="^003.toml: " + message):
        p003.load(_table(edit))


EKF_AT_50 = (
    '"N = 50", table = "N", n = 50, rows = ["a=1.0", "a=0.75", "a=0.5", "pf"]',
    '"N = 50", table = "N", n = 50, rows = ["a=1.0", "a=0.75", "a=0.5", "pf", "ekf"]',
)


def test_a_row_added_in_the_table_is_planned_without_code(monkeypatch):
    """Adding a row to a setting in the TOML (here the EKF at N = 50) plans its evaluation and nothing else; the
    slow test below checks that it reaches the document."""
    from replay.reproduce import p003

    before = {j.key for j in p003.plan(2, 2)}
    monkeypatch.setattr(p003, "T", p003.load(_table(EKF_AT_50)))
    after = {j.key: j for j in p003.plan(2, 2)}
    assert set(after) - before == {"N = 50|ekf|0"} and after["N = 50|ekf|0"].filter_params == {"ekf": {}}


@pytest.mark.slow
def test_a_row_added_in_the_table_reaches_the_document(tmp_path, monkeypatch):
    """The added row is a row of its sweep table, with its command."""
    from replay.reproduce import p003

    monkeypatch.setattr(p003, "T", p003.load(_table(EKF_AT_50)))
    p003.run(quick=True, runs=1, doc=tmp_path / "003.md", quiet=True)
    text = (tmp_path / "003.md").read_text(encoding="utf-8")
    assert (
        "| N = 50: EKF |" in text and "`replay eval sim/uav-formation --task formation --filters ekf --runs 1" in text
    )
