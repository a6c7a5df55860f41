"""What the parts of the paper-002 reproduction share: the paper's numbers, the settings, the job runner.

A part (:mod:`.p002_sim`, :mod:`.p002_ablations`, :mod:`.p002_bohai`) first lists
its configurations as :class:`Job` s, each one :func:`replay.run.evaluation.evaluate`
call (the pipeline of ``replay eval``); :func:`run_jobs` computes them in the
reproduction's worker processes (:mod:`replay.reproduce.pool`, ``REPLAY_WORKERS``,
the costliest first), with one progress line per configuration on stderr as it
finishes (``[3/17] tables: Table 5: pso-pf, pso-cpf unbounded (100 runs) done at 41 s``),
and the part renders Markdown and verdict claims from the evaluations.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from replay.data import registry
from replay.run.evaluation import evaluate

from .pool import run_longest_first

# --- the paper's numbers (../shared/seeds/README.md, paper 002) ---------------------------
UNGM_PAPER = {1.0: {"gwo-pf": 2.4984, "igwo-pf": 2.1829}, 10.0: {"gwo-pf": 5.2923, "igwo-pf": 4.1794}}
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
TABLE4 = {"stckf": 0.000366, "pf": 0.000634, "pso-pf": 0.009093, "pso-cpf": 0.017261, "igwo-stcpf": 0.007697}
R_SWEEP = {1: 1.3625, 5: 2.7283, 10: 2.9635}
N_SWEEP = {50: 1.2600, 100: 1.2842, 500: 1.1953}
BOHAI_PAPER = {"igwo-stcpf": 1.2853, "stckf": 3.6800, "pf": 6.6236, "pso-cpf": 3.4149}
BOHAI_DAY = "20220822"
BOHAI_ABLATION_SEQ = "bohai/20220822_0_6"

N100 = {"n_particles": 100}  # the paper's N for every particle filter (002 §4.1)
UNBOUNDED = {"lower": None, "upper": None}  # PSO without the 002 §4.1 box
PSO_LB = (-300.0, -300.0, -300.0, 0.0, -np.pi / 2, -np.pi)
PSO_UB = (300.0, 300.0, 0.0, 10.0, np.pi / 2, np.pi)
SONAR = ("sim/auv-sonar", "sonar")
UNGM = ("sim/ungm", "ungm")


@dataclass
class Settings:
    """Run counts of one reproduction (``runs`` None: the paper's; ``quick``: a smoke check)."""

    runs: int | None = None
    seed: int = 0
    data_dir: str | None = None
    quick: bool = False
    quiet: bool = False
    doc: Path = Path("docs/reproduction/002.md")

    @property
    def mc(self) -> int:  # Monte Carlo runs of a table (the paper: 100)
        return self.runs or (3 if self.quick else 100)

    @property
    def convergence(self) -> int:  # Fig. 9: 500
        return self.mc if (self.runs or self.quick) else 500

    @property
    def bohai_runs(self) -> int:  # issue 13: at least 20 per sequence
        return min(self.mc, 2) if self.quick else max(20, self.runs or 20)

    @property
    def bohai_first(self) -> int:
        return 200 if self.quick else 1000

    def png(self, name: str) -> Path:
        return self.doc.with_name(f"{self.doc.stem}_{name}.png")


@dataclass
class Job:
    """One :func:`replay.run.evaluation.evaluate` call: ``key`` names it among its part's jobs."""

    key: str
    label: str
    dataset: str
    task: str
    filters: tuple
    runs: int
    filter_params: dict = field(default_factory=dict)
    dataset_params: dict = field(default_factory=dict)
    task_params: dict = field(default_factory=dict)
    first: int | None = None
    data_dir: bool = False  # a file dataset: pass the settings' data_dir

    @property
    def cost(self) -> float:
        """Rough CPU cost (ms on one core): runs x steps x the filters' :data:`STEP_MS`, for
        :func:`run_jobs` to start the longest first."""
        steps = self.first or self.dataset_params.get("steps", 100)
        per_step = 0.0
        for f in self.filters:
            p = self.filter_params.get(f, {})
            ms = STEP_MS.get(f, 0.1) * p.get("n_particles", 1000 if f == "pf" else 100) / 100
            per_step += ms * (0.4 + 0.6 * p.get("t_max", 20) / 20 if "gwo" in f or "pso" in f else 1.0)
        return self.runs * steps * per_step


# CPU ms per run-step of each filter on sim/auv-sonar with N = 100 (one core, batches of 10 runs; for the
# longest-first order of run_jobs only: no number depends on it)
STEP_MS = {"stckf": 0.1, "ckf": 0.005, "pf": 0.03, "stcpf": 0.45, "igwo-stcpf": 0.85, "gwo-pf": 0.15,
           "igwo-pf": 0.15, "pso-pf": 0.5, "pso-cpf": 1.0}


def _evaluate(args):
    """One job's evaluation (what a worker process runs)."""
    j, seed, data_dir = args
    return evaluate(j.dataset, task=j.task, filters=j.filters, runs=j.runs, seed=seed, first=j.first,
                    data_dir=data_dir if j.data_dir else None, filter_params=j.filter_params or None,
                    dataset_params=j.dataset_params or None, task_params=j.task_params or None)


def run_jobs(jobs: list[Job], s: Settings, part: str, executor=None) -> dict:
    """Compute the jobs, the costliest first, in ``executor`` (a pool of :func:`replay.reproduce.pool.pool`;
    None: in this process): ``{key: Evaluation}`` in the jobs' order, one progress line per job on stderr.
    Every job draws from its own seeded streams: the numbers do not depend on the workers."""
    done = {}
    for i, ev in run_longest_first(_evaluate, [(j, s.seed, s.data_dir) for j in jobs], [j.cost for j in jobs],
                                   [f"{j.label} ({j.runs} runs)" for j in jobs], executor, s.quiet, f"{part}: "):
        done[i] = ev
    return {j.key: done[i] for i, j in enumerate(jobs)}


def bohai_sequences(data_dir) -> list[str]:
    """The 20220822 Bohai sequences found (the paper's 0_7 included when its file is supplied)."""
    ids = sorted(i for i in registry.all_datasets() if i.startswith(f"bohai/{BOHAI_DAY}_"))
    return [i for i in ids if registry.locate(i, data_dir) is not None]


def n100(*names, **more) -> dict:
    """Filter parameters: N = 100 for each of ``names``, plus ``more`` (name -> params)."""
    out = {n: dict(N100) for n in names}
    for n, p in more.items():
        out[n.replace("_", "-")] = dict(out.get(n.replace("_", "-"), {}), **p)
    return out
