"""Part ``bohai`` of the paper-002 reproduction: benchmark 3 on the Bohai AUV logs (002 §4.3).

``position`` task (3-D random walk, Q = I3, R = 2 I3, measurements synthesised
from the reference with seeded noise, P0 = 0.1 I3, first 1000 samples, N = 100)
on every 20220822 sequence found, at least 20 Monte Carlo runs each, with the
baselines (CKF, STCPF without optimiser). The swarm filters' fitness is the
measurement residual alone, so the optimiser converges to the measurement-only
fit: shown by the RMS distance between the estimate and the measurement, and by
T_max, the estimate before the move and the posterior-type fitness on one sequence.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from replay.reproduce.verdict import Claim, anchor

from .p002_common import BOHAI_ABLATION_SEQ, BOHAI_PAPER, Job, bohai_sequences, n100
from .p002_tables import add_paired, commands, entries, find, fmt, ok_runs, pm, table

FILTERS = ("igwo-stcpf", "stckf", "pf", "pso-cpf", "ckf", "stcpf")
NAMES = {"pf": "pf (N = 100)", "ckf": "ckf (baseline)", "stcpf": "stcpf (no optimiser)"}
H_BOHAI = "Benchmark 3: Bohai, position task (002 §4.3)"
H_FIT = "The optimiser converges to the measurement-only fit"
ABLATIONS = {"T_max = 20 (default)": {}, "T_max = 1": {"t_max": 1}, "T_max = 2": {"t_max": 2},
             "T_max = 5": {"t_max": 5}, "estimate before the move": {"estimate_at": "before"},
             "posterior-type fitness": {"fitness": "posterior"}}


def ablation_sequence(seqs):
    return BOHAI_ABLATION_SEQ if BOHAI_ABLATION_SEQ in seqs else seqs[-1]


def jobs(s) -> list[Job]:
    seqs = bohai_sequences(s.data_dir)
    if s.quick:
        seqs = seqs[-1:]
    out = [Job(f"seq:{ds}", f"{ds}: {', '.join(FILTERS)}", ds, "position", FILTERS, s.bohai_runs, n100("pf"),
               first=s.bohai_first, data_dir=True) for ds in seqs]
    if seqs:
        ds = ablation_sequence(seqs)
        for name, p in list(ABLATIONS.items())[1:]:
            out.append(Job(f"abl:{name}", f"{ds}: igwo-stcpf {name}", ds, "position", ("igwo-stcpf",), s.bohai_runs,
                           {"igwo-stcpf": p}, first=s.bohai_first, data_dir=True))
    return out


def fit_stats(e) -> dict:
    """RMS distance estimate - measurement and measurement - truth, share of steps with error < 2 m."""
    d_meas, d_raw, under = [], [], []
    for i in ok_runs(e.result):
        rec = e.result.records[i]
        pb, x = rec["problem"], rec["estimates"].x
        z, truth = pb.z, pb.truth_position
        ok = np.isfinite(z).all(axis=1) & pb.truth_valid
        d_meas.append(np.sum((x[ok, :3] - z[ok]) ** 2, axis=1))
        d_raw.append(np.sum((z[ok] - truth[ok]) ** 2, axis=1))
        err = e.result.errors[i]["position"]
        under.append(np.linalg.norm(err[np.isfinite(err).all(axis=1)], axis=1) < 2.0)
    return {"RMS estimate − measurement": f"{np.sqrt(np.concatenate(d_meas).mean()):.3f}",
            "raw measurement RMSE": np.sqrt(np.concatenate(d_raw).mean()),
            "steps with error < 2 m": f"{100 * np.concatenate(under).mean():.1f} %"}


def render(evs, s) -> tuple[list[str], list[Claim]]:
    seqs = [k[4:] for k in evs if k.startswith("seq:")]
    out = [f"## {H_BOHAI}", "",
           f"Q = I3, R = 2 I3 (measurements synthesised from the reference with seeded noise, so the raw "
           f"measurements have 3-D RMSE √6 ≈ 2.449 m), P0 = 0.1 I3, N = 100, one step per sample, first "
           f"{s.bohai_first} samples, {s.bohai_runs} Monte Carlo runs per sequence. The paper's sequence "
           "20220822_0_7 is not in our mirror; every 20220822 sequence found runs with the same protocol (0_7 runs "
           "unchanged when its file is supplied). Paired Δ: this row minus IGWO-STCPF. 'RMS estimate − "
           "measurement': how far the estimate stays from the measurement it was given (0: the measurement "
           "itself).", ""]
    if not seqs:
        out += ["No 20220822 sequence found (give `--data-dir`): not run.", ""]
        return out, [Claim("Bohai: IGWO-STCPF position RMSE 1.2853 m", "not run (no data)", "1.2853",
                           "not reproduced", anchor(H_BOHAI))]
    per, raw = {}, []
    for ds in seqs:
        rows = entries(evs[f"seq:{ds}"], NAMES, BOHAI_PAPER)
        add_paired(rows, "igwo-stcpf")
        for e in rows:
            st = fit_stats(e)
            raw.append(st.pop("raw measurement RMSE"))
            e.extra.update(st)
        per[ds] = rows
        out += [f"### {ds}", ""] + table(rows, ("paper", "pos", "ratio", "mean3", "median", "lost", "diverged",
                                               "paired", "RMS estimate − measurement", "steps with error < 2 m",
                                               "us"), "igwo-stcpf") + [""] + commands(rows)

    def mean_over(name, key="pos_rmse"):
        v = [find(rows, name).value(key) for rows in per.values()]
        return float(np.mean(v))

    out += [f"Mean over the {len(seqs)} sequences of the mean position RMSE: " + ", ".join(
        f"{find(next(iter(per.values())), n).name} {mean_over(n):.3f}" for n in
        ("igwo-stcpf", "stckf", "pf (N = 100)", "pso-cpf", "ckf (baseline)", "stcpf (no optimiser)")) +
        f" m; raw measurements {np.mean(raw):.3f} m.", ""]

    # ablations
    ds = ablation_sequence(seqs)
    rows = [find(per[ds], "igwo-stcpf")]
    rows[0] = replace(rows[0], name="igwo-stcpf, T_max = 20 (default)", extra=dict(rows[0].extra))
    rows += [entries(evs[f"abl:{n}"], {"igwo-stcpf": f"igwo-stcpf, {n}"})[0] for n in list(ABLATIONS)[1:]]
    rows += [find(per[ds], n) for n in ("stcpf (no optimiser)", "ckf (baseline)")]
    add_paired(rows, rows[0].name)
    for e in rows[1:-2]:
        st = fit_stats(e)
        st.pop("raw measurement RMSE")
        e.extra.update(st)
    out += [f"## {H_FIT}", "",
            f"On {ds}: the IGWO fitness is the measurement residual (z − x)ᵀ R⁻¹ (z − x) alone, so the wolves "
            "converge onto the particle nearest the measurement and the estimate follows the measurement: its "
            f"RMSE is that of the raw measurements (√6 ≈ 2.449 m for R = 2 I3) while the CKF, which weighs the "
            f"measurement against the random-walk prior, gets {pm(rows[-1].pair())} m. Fewer iterations, the "
            "estimate before the move, or a fitness with the transition term move it away from the measurement:",
            ""]
    out += table(rows, ("pos", "mean3", "median", "RMS estimate − measurement", "paired"), rows[0].name) + [""]
    out += commands(rows)

    igwo, pso, stckf, pf = (np.array([find(r, n).value() for r in per.values()]) for n in
                            ("igwo-stcpf", "pso-cpf", "stckf", "pf (N = 100)"))
    ckf = np.array([find(r, "ckf (baseline)").value() for r in per.values()])
    d_meas = [float(find(r, "igwo-stcpf").extra["RMS estimate − measurement"]) for r in per.values()]
    post = find(rows, "igwo-stcpf, posterior-type fitness")
    under = [find(r, "igwo-stcpf").extra["steps with error < 2 m"] for r in per.values()]
    span = lambda v: f"{v.min():.3f}–{v.max():.3f}"  # noqa: E731
    stcpf = np.array([find(r, "stcpf (no optimiser)").value() for r in per.values()])
    fits = bool(np.all(np.abs(igwo - np.mean(raw)) < 0.1))
    order = bool(np.all((igwo < pso) & (pso < stckf) & (stckf < pf)))
    near = lambda v, p: bool(np.all(np.abs(v - p) <= 0.1 * p))  # noqa: E731
    claims = [
        Claim("Bohai: IGWO-STCPF position RMSE 1.2853 m", f"{span(igwo)} over {len(seqs)} sequences "
              f"(raw measurements {np.mean(raw):.3f}; estimate − measurement {min(d_meas):.3f}–{max(d_meas):.3f})",
              "1.2853", "deviation explained" if fits else "not reproduced", anchor(H_FIT),
              "with the residual-only fitness the optimiser converges to the measurement-only fit (√6 = 2.449 m); "
              f"with a posterior-type fitness {pm(post.pair())} m on {ds}" if fits else ""),
        Claim("Bohai: IGWO-STCPF (1.2853) < PSO-CPF (3.4149) < STCKF (3.6800) < PF (6.6236)",
              f"IGWO-STCPF {span(igwo)}, PSO-CPF {span(pso)}, STCKF {span(stckf)}, PF {span(pf)}, CKF {span(ckf)}",
              "1.29 < 3.41 < 3.68 < 6.62", "reproduced" if order else "not reproduced", anchor(H_BOHAI)),
        Claim("Bohai: STCKF 3.6800 m and PF 6.6236 m", f"STCKF {span(stckf)}, PF {span(pf)}", "3.68, 6.62",
              "reproduced" if near(stckf, 3.68) and near(pf, 6.6236) else "not reproduced", anchor(H_BOHAI)),
        Claim("Bohai: IGWO-STCPF error stays under 2 m", f"steps under 2 m: {', '.join(under)}", "always",
              "reproduced" if all(u == "100.0 %" for u in under) else "not reproduced", anchor(H_BOHAI)),
        Claim("Bohai: IGWO in place of resampling improves the STCPF (implied)",
              f"STCPF {span(stcpf)} vs IGWO-STCPF {span(igwo)}", "not compared",
              "reproduced" if bool(np.all(igwo < stcpf)) else "not reproduced", anchor(H_BOHAI)),
    ]
    below = bool(np.all(stckf < np.mean(raw)) and np.all(pf < np.mean(raw)))
    out += [f"The paper's STCKF (3.68 m) and PF (6.62 m) are above the raw measurement error ({fmt(np.mean(raw))} m), "
            "which a filter that uses these measurements should not be; ours are "
            f"{'below' if below else '**not** all below'} it.", ""]
    return out, claims
