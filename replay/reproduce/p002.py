"""``replay reproduce 002``: the IGWO-STCPF paper as data: experiments, claims with rules, one template.

:data:`SIM` and :func:`bohai` list the experiments (dataset, task, rows: filter and parameters, the
paper's numbers); :mod:`.p002_claims` declares each claim with its rule (before any run) and the
comparisons it draws on; ``replay/papers/002.md`` holds the prose. Adding an ablation is a row here.
Every row is one :func:`replay.run.evaluation.evaluate` call's filter (the pipeline of ``replay eval``;
each table prints the commands that give its rows); rows of one experiment share the seed, so
they are paired run by run. Baselines at their best (``tune``): each listed filter's ``q_scale``
over the declared :data:`GRID`, chosen by the smallest mean position RMSE on the seed ``seed + 1``
(simulations, a fifth of the runs) or on the sequence :data:`TUNE_SEQ` (Bohai), then run on the
experiment's data.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace

import numpy as np

from replay.data import registry
from replay.run.evaluation import evaluate
from replay.run.manifest import command_line
from replay.models.auv_sonar import R_TABLE2

from .p002_claims import TUNE_SEQ
from replay.campaign.longest import pool, run_longest_first, workers
from .rules import per_run
from replay.util.portable import write_document

from .verdict import Stopwatch, footer

GRID = (0.01, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)  # q_scale of the tuned baselines, declared
COLS = ("pos_rmse", "x_rmse", "y_rmse", "pitch_rmse", "yaw_rmse")


@dataclass(frozen=True)
class Arm:
    """One row: ``label``, ``filter`` and its parameters, the paper's numbers (per column), dataset and
    task parameters of this row alone (sweeps)."""

    label: str
    filter: str
    params: dict = field(default_factory=dict)
    paper: tuple = ()
    dp: dict = field(default_factory=dict)
    tp: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Exp:
    key: str  # evidence anchor e-<key>
    title: str
    dataset: str
    task: str
    arms: tuple
    dp: dict = field(default_factory=dict)
    cols: tuple = ("pos_rmse",)
    tune: tuple = ()  # the filters tuned over GRID
    runs: str = "mc"  # "mc" (the paper's 100), "bohai" (20 per sequence), "tune" (a fifth of mc: the grids)
    first: int | None = None


def A(label, flt=None, paper=(), dp=None, tp=None, **params):
    return Arm(label, flt or label, params, paper if isinstance(paper, tuple) else (paper,), dp or {}, tp or {})


N100, UNB, QP = {"n_particles": 100}, {"lower": None, "upper": None}, {"prior_cov": "transition"}
MIX = {"mixture_eps": 0.05, "mixture_scale": 10.0}
TUNED = ("ckf", "stckf", "pf")
UNGM_ARMS = lambda g, i: (
    A("gwo-pf", paper=g),
    A("igwo-pf", paper=i),
    A("pf (N = 100)", "pf", **N100),  # noqa: E731
    A("ckf"),
    A("stcpf"),
)
T5 = (
    A("stckf", paper=(1.3373, 0.9998, 1.0090, 0.0790, 0.1117)),
    A("pf (N = 100)", "pf", (1.4222, 1.2044, 1.2016, 0.0804, 0.0937), **N100),
    A("pso-pf (bounded)", "pso-pf", (1.4818, 1.0420, 1.1079, 0.0913, 0.0909)),
    A("pso-cpf (bounded)", "pso-cpf", (1.4714, 1.0424, 1.0901, 0.0909, 0.0891)),
    A("igwo-stcpf", paper=(1.1579, 0.8775, 0.8808, 0.0602, 0.0760)),
    A("pso-pf (unbounded)", "pso-pf", **UNB),
    A("pso-cpf (unbounded)", "pso-cpf", **UNB),
    A("ckf"),
    A("stcpf (printed proposal)", "stcpf"),
    A("stcpf (Q prior)", "stcpf", **QP),
    A("igwo-stcpf (Q prior)", "igwo-stcpf", **QP),
    A("pf (N = 5000)", "pf", n_particles=5000),
    A("stckf (classic λ·FPFᵀ + Q)", "stckf", form="classic"),
    A("stckf (as printed)", "stckf", m_form="printed", scale_prior=False),
    A("stckf (as printed, repaired)", "stckf", m_form="printed", scale_prior=False, repair=True),
)
T6 = (
    A("pf (N = 100)", "pf", (3.3033, 1.3744, 1.4536, 0.0765, 0.1241), **N100),
    A("pso-pf (bounded)", "pso-pf", (2.3941, 1.0505, 1.1514, 0.0957, 0.1017)),
    A("pso-cpf (bounded)", "pso-cpf", (2.4627, 1.0518, 1.1496, 0.1008, 0.1029)),
    A("igwo-stcpf", paper=(1.5234, 0.9230, 0.9629, 0.0615, 0.0967)),
    A("pso-pf (unbounded)", "pso-pf", **UNB),
    A("pso-cpf (unbounded)", "pso-cpf", **UNB),
    A("ckf"),
    A("stcpf"),
    A("stckf"),
)
R5, R10 = {"R": (5 * R_TABLE2).tolist()}, {"R": (10 * R_TABLE2).tolist()}
SIM = (
    Exp(
        "ungm1",
        "UNGM, Q = R = 1 (002 §3.2)",
        "sim/ungm",
        "ungm",
        UNGM_ARMS(2.4984, 2.1829),
        {"q": 1.0, "r": 1.0},
        tune=("ckf", "pf"),
    ),
    Exp(
        "ungm10",
        "UNGM, Q = R = 10",
        "sim/ungm",
        "ungm",
        UNGM_ARMS(5.2923, 4.1794),
        {"q": 10.0, "r": 10.0},
        tune=("ckf", "pf"),
    ),
    Exp("t5", "Table 5: sonar, Gaussian noise", "sim/auv-sonar", "sonar", T5, cols=COLS, tune=TUNED),
    Exp("t6", "Table 6: sonar, mixed-Gaussian (glint) noise", "sim/auv-sonar", "sonar", T6, MIX, COLS, TUNED),
    Exp(
        "box",
        "Table 5 inside the paper's PSO box (truth without process noise, pitch 0.3 rad)",
        "sim/auv-sonar",
        "sonar",
        T5[:5] + (A("ckf"),),
        {"truth_noise": False, "x0": [0.0, 0.0, 0.0, 10.0, 0.3, np.pi / 10]},
        COLS,
    ),
    Exp(
        "sweep",
        "Fig. 17 and 18: IGWO-STCPF over R and N",
        "sim/auv-sonar",
        "sonar",
        (
            A("R1, N = 100", "igwo-stcpf", 1.3625),
            A("5 R1", "igwo-stcpf", 2.7283, R5, R5),
            A("10 R1", "igwo-stcpf", 2.9635, R10, R10),
            A("N = 50", "igwo-stcpf", 1.2600, n_particles=50),
            A("N = 500", "igwo-stcpf", 1.1953, n_particles=500),
        ),
    ),
)
B_ARMS = (
    A("igwo-stcpf"),
    A("pso-cpf"),
    A("stckf"),
    A("pf (N = 100)", "pf", **N100),
    A("ckf"),
    A("stcpf (printed proposal)", "stcpf"),
    A("stcpf (Q prior)", "stcpf", **QP),
    A("igwo-stcpf (Q prior)", "igwo-stcpf", **QP),
    A("raw measurements", "measurements"),
)
B_ABL = (
    A("igwo-stcpf, estimate before the move", "igwo-stcpf", estimate_at="before"),
    A("igwo-stcpf, posterior-type fitness", "igwo-stcpf", fitness="posterior"),
)


def bohai(seqs) -> list[Exp]:
    """Benchmark 3 on each sequence at the paper's T = 1 s and at the recording's 10 Hz (the
    rows at 10 Hz without the Q-prior ones), the optimiser ablations on the last sequence."""
    out = []
    for tag, dp, arms in (("1hz", {"rate": 1.0}, B_ARMS), ("10hz", {}, B_ARMS[:6] + B_ARMS[8:])):
        for s in seqs:
            out.append(
                Exp(
                    f"b{tag}-{s[-3:]}",
                    s,
                    s,
                    "position",
                    arms + (B_ABL if s == seqs[-1] else ()),
                    dp,
                    tune=TUNED,
                    runs="bohai",
                    first=1000,
                )
            )
    return out


def sequences(data_dir) -> list[str]:
    """The 20220822 Bohai sequences found (the paper's 0_7 too when its file is supplied)."""
    ids = sorted(i for i in registry.all_datasets() if i.startswith("bohai/20220822_"))
    return [i for i in ids if registry.locate(i, data_dir) is not None]


# --- running ----------------------------------------------------------------------------------------
def variants(e: Exp, qs, label: str) -> tuple:
    """The first row of each filter ``f`` of ``qs`` (filter -> q_scale values) with ``q_scale`` set:
    the tuned rows (one value each) or the grid (:data:`GRID`)."""
    base = {}
    for a in e.arms:
        base.setdefault(a.filter, a)
    return tuple(
        replace(
            base[f], label=label.format(f=f, q=q, base=base[f].label), paper=(), params=dict(base[f].params, q_scale=q)
        )
        for f, v in qs.items()
        for q in v
    )


def q_for(e: Exp, chosen: dict) -> dict:
    """The tuned q_scale of each of ``e.tune``: its own seed + 1 grid (simulations), the tuning
    sequence's at the same rate (Bohai; none on the tuning sequence itself)."""
    if e.runs == "mc":
        return chosen.get(e.key, {})
    return {} if e.dataset == TUNE_SEQ else chosen.get(f"{e.key.split('-')[0]}-{TUNE_SEQ[-3:]}", {})


def jobs(exps, s: dict) -> list[tuple]:
    """Pack each experiment's rows into evaluate calls: one call per distinct dataset and task
    parameters, each filter once per call. A job: (exp key, ((label, filter, params), ...), kwargs)."""
    out = []
    for e in exps:
        calls = []
        for a in e.arms:
            if a.filter == "measurements":
                continue
            key = json.dumps([dict(e.dp, **a.dp), a.tp], sort_keys=True)
            c = next((c for c in calls if c[0] == key and a.filter not in {x[1] for x in c[1]}), None)
            if c is None:
                calls.append(c := (key, []))
            c[1].append((a.label, a.filter, a.params))
        runs = s[e.runs]
        for key, rows in calls:
            dp, tp = json.loads(key)
            out.append(
                (
                    e.key,
                    tuple(rows),
                    dict(
                        dataset=e.dataset,
                        task=e.task,
                        runs=runs,
                        first=e.first,
                        seed=s["seed"] + (e.runs == "tune"),
                        dataset_params=dp or None,
                        task_params=tp or None,
                        data_dir=s["data_dir"] if e.runs == "bohai" else None,
                    ),
                )
            )
    return out


def compute(job) -> dict:
    """One evaluate call (a worker process), reduced to what the document and the claims use."""
    _, rows, kw = job
    ev = evaluate(filters=tuple(f for _, f, _ in rows), filter_params={f: p for _, f, p in rows if p} or None, **kw)
    by = {r.name: r for r in ev.results}
    out = {"command": command_line(ev.config), "labels": {lab: f for lab, f, _ in rows}, "rows": {}}
    z_low = [
        float(np.mean(t[:, 2] < -300.0)) for t in ev.truths if t.shape[1] > 2
    ]  # the PSO box's depth bound (002 §4.1)
    for lab, f in list(out["labels"].items()) + [("raw measurements", "measurements")]:
        if f in by:
            r, (v, lost) = by[f], per_run(by[f])
            above = [float(np.mean(np.linalg.norm(e["position"], axis=1) > 2.0)) for e in r.errors]
            out["rows"][lab] = {
                "row": {
                    k: r.summary.get(k)
                    for k in r.summary
                    if k.endswith(("rmse", "ci95", "median")) or k in ("lost", "diverged", "runs", "us_per_step")
                },
                "v": v.tolist(),
                "lost": lost.tolist(),
                "above2": above,
                "z_low": float(np.mean(z_low)) if z_low else None,
                "cols": {c: per_run(r, c)[0].tolist() for c in COLS if c in r.runs[0]},
            }
    return out


def run_all(exps, s, ex) -> dict:
    """{exp key: {label: row evidence, ...}, "cmd:<key>": [commands]} of every experiment."""
    todo = jobs(exps, s)
    cost = [
        kw["runs"]
        * (kw["first"] or 100)
        * sum(5 if "gwo" in f or "pso" in f or "stcpf" in f else 1 for _, f, _ in rows)
        for _, rows, kw in todo
    ]
    E = {}
    for i, out in run_longest_first(
        compute, todo, cost, [f"{k}: {', '.join(r[0] for r in rows)}" for k, rows, _ in todo], ex, s["quiet"], "002 "
    ):
        k = todo[i][0]
        cmds = E.setdefault(f"cmd:{k}", [])
        cmds.append(out["command"])
        E.setdefault(k, {}).update({lab: dict(r, cmd=len(cmds)) for lab, r in out["rows"].items()})
    return E


def tune(exps, s, ex) -> dict:
    """{exp key: {filter: chosen q_scale}} from the grids (module docstring)."""
    grids = [
        replace(
            e,
            key=f"{e.key}:grid",
            runs="tune" if e.runs == "mc" else e.runs,
            arms=variants(e, {f: GRID for f in e.tune}, "{f} q×{q:g}"),
        )
        for e in exps
        if e.tune and (e.runs != "bohai" or e.dataset == TUNE_SEQ)
    ]
    E, chosen = run_all(grids, s, ex), {}
    for g in grids:
        for a in g.arms:
            best = chosen.setdefault(g.key.split(":")[0], {}).get(a.filter)
            m = np.mean(E[g.key][a.label]["v"])
            if best is None or m < best[0]:
                chosen[g.key.split(":")[0]][a.filter] = (m, a.params["q_scale"])
    return {k: {f: q for f, (_, q) in v.items()} for k, v in chosen.items()}


def compute_all(runs, seed, data_dir, quick, quiet) -> tuple:
    """(experiments with their tuned rows, evidence, chosen q_scale, Bohai sequences)."""
    seqs = sequences(data_dir)
    mc = runs or (3 if quick else 100)
    s = {
        "seed": seed,
        "data_dir": data_dir,
        "quiet": quiet,
        "mc": mc,
        "tune": max(2, mc // 5),
        "bohai": 2 if quick else max(20, runs or 20),
    }
    exps = list(SIM) + bohai(seqs[-2:] if quick else seqs)
    with pool(workers()) as ex:
        chosen = tune(exps, s, ex)
        exps = [
            replace(e, arms=e.arms + variants(e, {f: (q,) for f, q in q_for(e, chosen).items()}, "{base}, q tuned"))
            for e in exps
        ]
        return exps, run_all(exps, s, ex), chosen, seqs


def run(runs=None, seed=0, data_dir=None, doc=None, quick=False, quiet=False):
    """Compute every experiment, decide the claims, write the document."""
    from . import p002_claims

    watch = Stopwatch()
    exps, E, chosen, seqs = compute_all(runs, seed, data_dir, quick, quiet)
    cmd = (
        "replay reproduce 002"
        + (f" --runs {runs}" if runs else "")
        + (" --quick" if quick else "")
        + f" --seed {seed}"
        + (" --data-dir ../shared/datasets/bohai" if data_dir else "")
    )
    text = p002_claims.document(exps, E, chosen, seqs, seed)
    path = write_document(doc or "docs/reproduction/002.md", text + footer(cmd, watch.seconds))
    if not quiet:
        print(f"wrote {path} ({watch.seconds:.0f} s)")
    return path
