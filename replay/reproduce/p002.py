"""``replay reproduce 002``: every published number of the IGWO-STCPF paper beside ours.

Table 5 is run with 500 Monte Carlo runs (the paper's convergence figure,
Fig. 9); the table is taken from the first 100 of them, which are exactly the
numbers of a 100-run ``replay eval`` (each run's seeds depend only on the
seed and the run index).

Three experiments, each a plain :func:`replay.evaluate.evaluate` call (so each
table can be repeated with the ``replay eval`` command printed beside it, and
all filters of a table see the same noise in a run: paired comparisons):

1. ``sim/ungm`` (benchmark 1): GWO-PF vs IGWO-PF, Q = R = 1 and Q = R = 10.
2. ``sim/auv-sonar`` (benchmark 2): Table 5 (Gaussian noise), Table 6 (mixed
   Gaussian, eps = 0.05, R2 = 10 R1), the R sweep (R1, 5 R1, 10 R1) and the
   particle sweep (N = 50, 100, 500) of IGWO-STCPF.
3. Bohai (benchmark 3): ``position`` task, first 1000 samples, Q = I3,
   R = 2 I3, P0 = 0.1 I3, N = 100, on every 20220822 sequence found (0_7, the
   paper's, is used unchanged when present).

"Position error" (the paper's is smaller than sqrt(X^2 + Y^2) of its own
table): we compute several definitions from the same errors and report which
one reproduces the paper's ratio position / sqrt(X^2 + Y^2).
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from replay import registry
from replay import score
from replay.evaluate import FilterResult, command_line, evaluate
from replay.models.auv_sonar import R_TABLE2
from replay.score import ci95

FIVE = ("stckf", "pf", "pso-pf", "pso-cpf", "igwo-stcpf")
N100 = {"pf": {"n_particles": 100}}

UNGM_PAPER = {(1.0, 1.0): {"gwo-pf": 2.4984, "igwo-pf": 2.1829},
              (10.0, 10.0): {"gwo-pf": 5.2923, "igwo-pf": 4.1794}}
COLS = ("position", "x", "y", "pitch", "yaw")
TABLE5 = {"stckf": (1.3373, 0.9998, 1.0090, 0.0790, 0.1117),
          "pf": (1.4222, 1.2044, 1.2016, 0.0804, 0.0937),
          "pso-pf": (1.4818, 1.0420, 1.1079, 0.0913, 0.0909),
          "pso-cpf": (1.4714, 1.0424, 1.0901, 0.0909, 0.0891),
          "igwo-stcpf": (1.1579, 0.8775, 0.8808, 0.0602, 0.0760)}
TABLE6 = {"pf": (3.3033, 1.3744, 1.4536, 0.0765, 0.1241),
          "pso-pf": (2.3941, 1.0505, 1.1514, 0.0957, 0.1017),
          "pso-cpf": (2.4627, 1.0518, 1.1496, 0.1008, 0.1029),
          "igwo-stcpf": (1.5234, 0.9230, 0.9629, 0.0615, 0.0967)}
R_SWEEP = {1: 1.3625, 5: 2.7283, 10: 2.9635}
N_SWEEP = {50: 1.2600, 100: 1.2842, 500: 1.1953}
BOHAI_PAPER = {"igwo-stcpf": 1.2853, "stckf": 3.6800, "pf": 6.6236, "pso-cpf": 3.4149}
BOHAI_DAY = "20220822"


# --- position-error definitions ------------------------------------------------------
def position_definitions(errors: list[np.ndarray]) -> dict[str, np.ndarray]:
    """Per-run values of each candidate definition from per-run (n, 3) error arrays."""
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
    "rmse3": "3-D RMSE sqrt(mean_k |e_k|^2) = sqrt(X^2+Y^2+Z^2) (the scorer's pos_rmse)",
    "rmse2": "horizontal RMSE sqrt(mean_k (ex^2+ey^2)) = sqrt(X^2+Y^2)",
    "mean3": "mean over steps of the 3-D Euclidean error |e_k|",
    "mean2": "mean over steps of the horizontal Euclidean error",
}


# --- one table -----------------------------------------------------------------------
def cell(values):
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return (float(v.mean()) if len(v) else float("nan")), ci95(v)


def table_rows(ev, paper: dict, reference: str | None = "igwo-stcpf"):
    """Rows: filter, then per column (paper, ours, ci, ratio), plus paired Δ of position vs ``reference``."""
    per = {}
    for r in ev.results:
        ok = [i for i, m in enumerate(r.runs) if not m["diverged"]]
        pos = position_definitions([r.errors[i]["position"] for i in ok])
        runs = [r.runs[i] for i in ok]
        per[r.name] = {"position": pos["rmse3"], "defs": pos,
                       "x": np.array([m["x_rmse"] for m in runs]), "y": np.array([m["y_rmse"] for m in runs]),
                       "pitch": np.array([m.get("pitch_rmse", np.nan) for m in runs]),
                       "yaw": np.array([m.get("yaw_rmse", np.nan) for m in runs]),
                       "diverged": len(r.runs) - len(ok), "us": r.summary["us_per_step"], "ok": ok}
    rows = []
    for name, p in per.items():
        row = {"filter": name, "diverged": p["diverged"], "runs": len(p["ok"]) + p["diverged"], "us": p["us"],
               "defs": {k: cell(v) for k, v in p["defs"].items()}}
        for j, col in enumerate(COLS):
            mean, ci = cell(p[col])
            pv = paper.get(name, (np.nan,) * 5)[j]
            row[col] = (pv, mean, ci, mean / pv if pv == pv else np.nan)
        if reference in per and name != reference:
            a = dict(zip(p["ok"], p["position"]))
            b = dict(zip(per[reference]["ok"], per[reference]["position"]))
            both = sorted(set(a) & set(b))
            row["paired"] = cell([a[i] - b[i] for i in both])
        rows.append(row)
    return rows


def fmt(x, digits=4):
    return "nan" if not np.isfinite(x) else f"{x:.{digits}f}"


def md_table(rows, title: str, command: str, note: str = "") -> list[str]:
    head = ["filter"] + [f"{c} paper / ours ± 95 % / ratio" for c in COLS] + \
        ["Δ position vs IGWO-STCPF (paired) ± 95 %", "µs/step", "diverged"]
    lines = [f"### {title}", "", f"`{command}`", ""]
    if note:
        lines += [note, ""]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["filter"]]
        for c in COLS:
            pv, mean, ci, ratio = r[c]
            cells.append(f"{fmt(pv)} / {fmt(mean)} ± {fmt(ci)} / {fmt(ratio, 2)}")
        pd = r.get("paired")
        cells.append(f"{fmt(pd[0])} ± {fmt(pd[1])}" if pd else "—")
        cells += [f"{r['us']:.0f}", f"{r['diverged']}/{r['runs']}"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def print_rows(rows, title):
    print(f"\n== {title}")
    print(f"{'filter':12s} " + "  ".join(f"{c:>30s}" for c in COLS))
    for r in rows:
        cells = []
        for c in COLS:
            pv, mean, ci, ratio = r[c]
            cells.append(f"{fmt(pv):>7s} {fmt(mean):>7s}±{fmt(ci):6s} x{fmt(ratio, 2):>5s}")
        print(f"{r['filter']:12s} " + "  ".join(f"{x:>30s}" for x in cells))


# --- Monte Carlo convergence (Fig. 9: 500 runs) -------------------------------------
CONVERGENCE_RUNS = 500


def path_for(doc) -> Path:
    return Path(doc) if doc else Path(__file__).resolve().parents[2] / "docs" / "reproduction" / "002.md"


def first_runs(ev, n: int):
    """The evaluation restricted to its first ``n`` runs: the numbers of an ``n``-run evaluation
    (each run's seeds depend only on (seed, run))."""
    if ev.config["runs"] == n:
        return ev
    results = [FilterResult(r.name, r.params, r.runs[:n], r.errors[:n], r.estimates[:n],
                            score.aggregate(r.runs[:n])) for r in ev.results]
    return replace(ev, config=dict(ev.config, runs=n), results=results, truths=ev.truths[:n])


def convergence(ev, png: Path) -> list[str]:
    """Fig. 9: per-run position RMSE against the Monte Carlo trial index, and its running mean."""
    n = ev.config["runs"]
    marks = [m for m in (10, 50, 100, 200, 500, n) if m <= n]
    marks = sorted(set(marks))
    lines = [f"### Convergence over Monte Carlo trials (Fig. 9): {n} runs, Table 5 setup", "",
             "Running mean of the per-run position RMSE (m) after the first m runs ± 95 % "
             "(diverged runs left out); the same runs as Table 5 (its first 100).", "",
             "| filter | " + " | ".join(f"m = {m}" for m in marks) + " |", "|" + "---|" * (len(marks) + 1)]
    series = {}
    for r in ev.results:
        v = np.array([np.nan if m["diverged"] else m["pos_rmse"] for m in r.runs])
        series[r.name] = v
        lines.append(f"| {r.name} | " + " | ".join(f"{fmt(cell(v[:m])[0])} ± {fmt(cell(v[:m])[1])}"
                                                   for m in marks) + " |")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return lines + ["", "(plot skipped: matplotlib is not installed)", ""]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    idx = np.arange(1, n + 1)
    for name, v in series.items():
        ok = np.isfinite(v)
        run_mean = np.cumsum(np.where(ok, v, 0.0)) / np.maximum(np.cumsum(ok), 1)
        line, = ax.plot(idx, run_mean, lw=2, label=name)
        ax.plot(idx[ok], v[ok], ".", ms=2, alpha=0.3, color=line.get_color())
    ax.set_yscale("log")
    ax.set_xlabel("Monte Carlo trial")
    ax.set_ylabel("position RMSE (m): per trial (dots), running mean (lines)")
    ax.set_title(f"paper 002, sim/auv-sonar, Table 5 setup, {n} trials")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return lines + ["", f"![convergence]({png.name})", ""]


# --- the experiments ---------------------------------------------------------------
def bohai_sequences(data_dir):
    ids = sorted(i for i in registry.all_datasets() if i.startswith(f"bohai/{BOHAI_DAY}_"))
    return [i for i in ids if registry.locate(i, data_dir) is not None]


def cmd(ev, extra=""):
    return command_line(ev.config) + extra


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False):
    started = time.perf_counter()
    mc = runs or (3 if quick else 100)
    bohai_runs = min(mc, 2 if quick else 3)
    first = 200 if quick else 1000
    n_sweep = (50, 100) if quick else (50, 100, 500)
    out = ["# Reproduction of paper 002 (IGWO-STCPF)", "",
           "Generated by `replay reproduce 002" + (f" --runs {runs}" if runs else "") +
           (" --quick" if quick else "") + f" --seed {seed}" +
           (f" --data-dir {data_dir}" if data_dir else "") + "`; do not edit by hand.",
           f"Monte Carlo runs: {mc} (Bohai: {bohai_runs}); seed {seed}. Each cell: the paper's value / "
           "ours (mean over runs of the per-run RMSE) ± half-width of its 95 % Student-t interval / "
           "ratio ours ÷ paper. All filters of a table run on the same noise in each run "
           "(seeds (seed, run, stream), see replay/evaluate.py), so the paired Δ column has tight intervals.", ""]
    timings = {}

    # 1. UNGM
    out += ["## Benchmark 1: UNGM, PF with GWO vs IGWO resampling (002 §3.2)", "",
            "| Q = R | filter | paper RMSE | ours ± 95 % | ratio | paired Δ IGWO − GWO ± 95 % | command |",
            "|---|---|---|---|---|---|---|"]
    print("== Benchmark 1: UNGM")
    for (q, r), paper in UNGM_PAPER.items():
        t0 = time.perf_counter()
        ev = evaluate("sim/ungm", task="ungm", filters=("gwo-pf", "igwo-pf"), runs=mc, seed=seed,
                      dataset_params={"q": q, "r": r})
        timings[f"ungm q=r={q:g}"] = time.perf_counter() - t0
        vals = {res.name: np.array([m["pos_rmse"] for m in res.runs]) for res in ev.results}
        d = cell(vals["igwo-pf"] - vals["gwo-pf"])
        for name in ("gwo-pf", "igwo-pf"):
            mean, ci = cell(vals[name])
            print(f"Q=R={q:g} {name:8s} paper {paper[name]:.4f} ours {mean:.4f} ±{ci:.4f} ratio {mean / paper[name]:.2f}")
            out.append(f"| {q:g} | {name} | {paper[name]:.4f} | {mean:.4f} ± {ci:.4f} | {mean / paper[name]:.2f} | "
                       + (f"{d[0]:.4f} ± {d[1]:.4f}" if name == "igwo-pf" else "") +
                       f" | `{cmd(ev)}` |")
    out += [""]

    # 2. AUV sonar
    out += ["## Benchmark 2: simulated AUV tracked by a sonar (002 §4, Table 2)", ""]
    t0 = time.perf_counter()
    conv = max(mc, CONVERGENCE_RUNS) if not (runs or quick) else mc
    ev_all = evaluate("sim/auv-sonar", task="sonar", filters=FIVE, runs=conv, seed=seed, filter_params=N100)
    timings[f"table 5 ({conv} runs: table from the first {mc}, convergence from all)"] = time.perf_counter() - t0
    ev5 = first_runs(ev_all, mc)
    rows5 = table_rows(ev5, TABLE5)
    print_rows(rows5, "Table 5 (Gaussian noise)")
    out += md_table(rows5, "Table 5: Gaussian measurement noise", cmd(ev5, " -p pf.n_particles=100"))
    position_fit = [("Table 5", rows5, TABLE5)]
    out += convergence(ev_all, path_for(doc).with_name("002_convergence.png"))

    t0 = time.perf_counter()
    ev6 = evaluate("sim/auv-sonar", task="sonar", filters=FIVE[1:], runs=mc, seed=seed, filter_params=N100,
                   dataset_params={"mixture_eps": 0.05, "mixture_scale": 10.0})
    timings["table 6"] = time.perf_counter() - t0
    rows6 = table_rows(ev6, TABLE6)
    print_rows(rows6, "Table 6 (mixed Gaussian noise)")
    out += md_table(rows6, "Table 6: mixed-Gaussian noise (1 − ε) N(0, R1) + ε N(0, 10 R1), ε = 0.05",
                    cmd(ev6, " -p pf.n_particles=100"),
                    "The filters assume N(0, R1) (they are not told about the outliers).")
    position_fit.append(("Table 6", rows6, TABLE6))

    # sweeps (IGWO-STCPF only); R1 and N = 100 are Table 5's IGWO-STCPF runs
    igwo5 = next(r for r in rows5 if r["filter"] == "igwo-stcpf")["position"]
    sweep = ["### Sweeps of IGWO-STCPF position RMSE (Fig. 17, Fig. 18)", "",
             "| sweep | paper | ours ± 95 % | ratio |", "|---|---|---|---|"]
    print("\n== sweeps (IGWO-STCPF position RMSE)")
    for mult, paper in R_SWEEP.items():
        if mult == 1:
            mean, ci = igwo5[1], igwo5[2]
        else:
            t0 = time.perf_counter()
            R = (mult * R_TABLE2).tolist()
            ev = evaluate("sim/auv-sonar", task="sonar", filters=("igwo-stcpf",), runs=mc, seed=seed,
                          dataset_params={"R": R}, task_params={"R": R})
            timings[f"R sweep {mult}"] = time.perf_counter() - t0
            mean, ci = cell([m["pos_rmse"] for m in ev.results[0].runs if not m["diverged"]])
        print(f"R = {mult:>3d} R1  paper {paper:.4f}  ours {mean:.4f} ±{ci:.4f}  ratio {mean / paper:.2f}")
        sweep.append(f"| R = {mult} R1 | {paper:.4f} | {mean:.4f} ± {ci:.4f} | {mean / paper:.2f} |")
    for n in n_sweep:
        paper = N_SWEEP[n]
        if n == 100:
            mean, ci = igwo5[1], igwo5[2]
        else:
            t0 = time.perf_counter()
            ev = evaluate("sim/auv-sonar", task="sonar", filters=("igwo-stcpf",), runs=mc, seed=seed,
                          filter_params={"igwo-stcpf": {"n_particles": n}})
            timings[f"N sweep {n}"] = time.perf_counter() - t0
            mean, ci = cell([m["pos_rmse"] for m in ev.results[0].runs if not m["diverged"]])
        print(f"N = {n:>4d}     paper {paper:.4f}  ours {mean:.4f} ±{ci:.4f}  ratio {mean / paper:.2f}")
        sweep.append(f"| N = {n} | {paper:.4f} | {mean:.4f} ± {ci:.4f} | {mean / paper:.2f} |")
    out += sweep + ["", "The R sweep scales both the simulated noise and the filter's R "
                    "(`dataset_params R`, `task_params R`).", ""]

    # 3. Bohai
    out += ["## Benchmark 3: Bohai, `position` task, first 1000 samples (002 §4.3)", "",
            "Q = I3, R = 2 I3 (measurements synthesised from the reference with seeded noise), "
            "P0 = 0.1 I3, N = 100, one step per sample. The paper's sequence 20220822_0_7 is not in our "
            "mirror; every 20220822 sequence found is run with the same protocol (0_7 runs unchanged "
            "when its file is supplied).", ""]
    seqs = bohai_sequences(data_dir)
    print("\n== Benchmark 3: Bohai")
    if not seqs:
        out += ["No 20220822 sequence found (give `--data-dir`): not run.", ""]
        print("no 20220822 sequence found: skipped")
    else:
        names = tuple(BOHAI_PAPER)
        out += ["| sequence | " + " | ".join(f"{n} (paper {BOHAI_PAPER[n]:.4f}) ours ± 95 %" for n in names)
                + " | command |", "|" + "---|" * (len(names) + 2)]
        for ds in seqs:
            t0 = time.perf_counter()
            ev = evaluate(ds, task="position", filters=names, runs=bohai_runs, seed=seed, first=first,
                          data_dir=data_dir, filter_params=N100)
            timings[ds] = time.perf_counter() - t0
            cells = []
            for r in ev.results:
                mean, ci = cell([m["pos_rmse"] for m in r.runs if not m["diverged"]])
                cells.append(f"{mean:.4f} ± {ci:.4f}")
            print(f"{ds:22s} " + "  ".join(f"{n}={c}" for n, c in zip(names, cells)))
            out.append(f"| {ds} | " + " | ".join(cells) + f" | `{cmd(ev, ' -p pf.n_particles=100')}` |")
        out += ["", "Position error here is the 3-D RMSE (z is constant and not observed in the Bohai files, "
                "so the vertical error is the filter's measurement-noise residual only).", ""]

    # position-error definitions
    out += ["## Which \"position error\"?", "",
            "The paper's position error is smaller than sqrt(X² + Y²) of its own tables (e.g. Table 5 STCKF: "
            "1.3373 < sqrt(0.9998² + 1.0090²) = 1.4205), so it is not a horizontal RMSE. Ours, from the same "
            "runs, under each definition (mean over runs ± 95 %), and the ratio definition ÷ sqrt(X² + Y²) "
            "beside the paper's ratio position ÷ sqrt(X² + Y²):", ""]
    for key, text in DEFINITIONS.items():
        out.append(f"* `{key}`: {text}")
    out += ["", "| table | filter | paper ratio | " + " | ".join(f"{k} (ratio)" for k in DEFINITIONS) + " |",
            "|" + "---|" * (3 + len(DEFINITIONS))]
    fit = {k: [] for k in DEFINITIONS}
    for title, rows, paper in position_fit:
        for r in rows:
            p = paper[r["filter"]]
            pr = p[0] / np.hypot(p[1], p[2])
            h = np.hypot(r["x"][1], r["y"][1])
            cells = []
            for k in DEFINITIONS:
                v, ci = r["defs"][k]
                fit[k].append(abs(v / h - pr))
                cells.append(f"{v:.4f} ± {ci:.4f} ({v / h:.3f})")
            out.append(f"| {title} | {r['filter']} | {pr:.3f} | " + " | ".join(cells) + " |")
    best = min(fit, key=lambda k: np.mean(fit[k]))
    out += ["", f"Closest to the paper's ratios (mean absolute difference of ratios): `{best}` "
            f"({', '.join(f'{k} {np.mean(v):.3f}' for k, v in fit.items())}). The tables above report "
            "`rmse3` as 'position'.", ""]
    print(f"\nposition-error definition closest to the paper's ratios: {best}")

    elapsed = time.perf_counter() - started
    out += ["## Timing", "", f"Whole reproduction: {elapsed:.0f} s on this machine.", "",
            "| experiment | seconds |", "|---|---|"] + [f"| {k} | {v:.1f} |" for k, v in timings.items()] + [""]
    out += NOTES.splitlines()
    path = path_for(doc)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    print(f"\nwrote {path} ({elapsed:.0f} s)")
    return path


NOTES = """## Where we do not match, and what was tried

* The models and algorithms follow the paper where it is explicit; every ambiguity is decided in the
  docstring of the module that implements it (`filters/stckf.py`, `filters/stcpf.py`, `filters/gwo.py`,
  `filters/pso.py`, `filters/igwo_stcpf.py`, `replay/models/ungm.py`, `replay/sim/auv_sonar.py`).
  Nothing was tuned toward the paper's numbers.
* GWO/IGWO and PSO "replace resampling" and their fitness is the measurement residual only. With 20
  iterations the wolves converge onto the best-fitting particles, so the swarm filters' estimate is close
  to the measurement-only best fit: on the Bohai position task IGWO-STCPF and PSO-CPF give about sqrt(6) =
  2.45 m, the RMSE of the raw R = 2 I3 measurements, where the paper reports 1.29 m. Tried: taking the
  estimate before the move (`-p igwo-stcpf.estimate_at=before`): better on Bohai (about 1.85 m on 0_6),
  worse on sim/auv-sonar (5 runs: 4.6 m against 3.3 m); neither beats STCPF without the optimiser.
* STCKF: `m_form="propagated"` (M = H Φ P Φ' H') and `scale_prior=True` by default; as printed
  (`scale_prior=False`) the per-particle covariances lose positive definiteness thousands of times per
  run (counted in `info["covariance_repairs"]`).
* The simulated AUV (replay/sim/auv_sonar.py) applies Q = diag(1, 1, 1, 0.1, 0.01, 0.01) as a random walk
  to speed, pitch and yaw: many trajectories dive below -300 m (to about -1100 m), outside the paper's
  PSO bounds (z in [-300, 0]); with those bounds PSO-PF and PSO-CPF clip the particles and lose the
  track in such runs. Ranges of several hundred metres make the 0.01 rad bearing noise several metres
  across, which is why all our sonar RMSEs are larger than the paper's.
* The IGWO entropy weights are almost equal (w* = 1 − E ∈ [0.63, 1]): IGWO differs from GWO mainly
  through its convergence factor.
* Speed: the particle-level work of STCPF, IGWO-STCPF and PSO-CPF (per-particle cubature filters, GWO
  moves) runs as compiled kernels (`filters/compiled.py`); the µs/step column is the batch's step time
  divided by its runs. `benchmarks/bench_002.py` times one run and a batch against the paper's Table 4.
"""
